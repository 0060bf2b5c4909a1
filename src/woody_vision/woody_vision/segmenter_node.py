"""segmenter: top-down depth frames in, tracked fillet contours out (/vision/tracks).

Thin adapter over woody_vision.belt_view, woody_vision.segmentation and woody_vision.tracking: a camera
mounted off straight down, turned, off the belt's middle or with lens distortion (camera_info D, its pose
on tf_static) has its frames resampled into its straight-down belt view first. The
empty-belt background is learned from the first frames (publish on
~/reset_background to relearn it); every bad frame is skipped with one log
line so a camera hiccup never takes the node down or corrupts its tracks.
With ``color_threshold`` > 0 the outline comes from the registered colour
frame nearest the depth frame's stamp within ``color_sync_tolerance_s``
(woody_vision.frame_pairing; a depth frame waits for it at most until two more
depth frames arrive; one without such a colour frame is skipped like a lost
frame, so no depth-only outline, which is another shape, enters a fillet's
score).
When sim time goes back (/clock or the depth stamps; a replay started again,
a restarted camera or line) the background is relearned and every track
dropped, with one log line, so a second pass is segmented like the first.
"""

from __future__ import annotations

import array
import sys

import cv2
import numpy as np
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Empty

from woody_common import topics
from woody_common.diagnostics import ERROR, OK, WARN, DiagnosticsPublisher, Health
from woody_common.images import serialized_image
from woody_common.line import (
    DEPTH_UNIT_M,
    LANE_PITCH_M,
    LANE_PITCH_RANGE_M,
    LANES,
    MAX_FILLET_AREA_M2,
    MAX_FILLET_LENGTH_M,
    MAX_FILLET_WIDTH_M,
    MAX_LANES,
    TOP_CAMERA_HEIGHT_M,
)
from woody_common.ros_params import declare, run_node
from woody_common.stamps import stamp_to_nanoseconds, stamp_to_seconds
from woody_msgs.msg import FilletTrack, FilletTrackArray, FilletVerdict
from woody_vision import segmentation
from woody_vision.belt_view import BeltView, CameraModel, straight_down_pose
from woody_vision.camera_model import LaneLayout, belt_outline
from woody_vision.frame_checks import FrameChecker, FrameError, SimTimeWatch, watch_clock
from woody_vision.frame_pairing import HELD_DEPTH_FRAMES, MAX_HELD_DEPTH_FRAMES, FramePairing, Pair
from woody_vision.image_encodings import color_rgb, depth_metres, match_size
from woody_vision.image_qos import declare_image_qos
from woody_vision.mount_watch import MountWatch
from woody_vision.segmentation import (
    HEIGHT_CORE_RATIO,
    BackgroundModel,
    SegmentationParams,
    segment_depth,
)
from woody_vision.tracking import CentroidTracker


class Segmenter(Node):
    """Depth background subtraction + watershed + centroid tracking for every lane at once."""

    def __init__(self) -> None:
        super().__init__("segmenter")
        segmentation.warm_up()  # before any subscription: no frame waits for a compile
        self.params = self._declare_segmentation()
        self.lanes = declare(self, "lanes", LANES, "Lanes across the belt.", 1, MAX_LANES)
        self.lane_pitch = declare(self, "lane_pitch_m", LANE_PITCH_M, "Lane centre to centre (m).", *LANE_PITCH_RANGE_M)
        self.max_fillet_width = declare(self, "max_fillet_width_m", MAX_FILLET_WIDTH_M, "A blob wider across the "
                                        "flow than this is checked for two fillets side by side (m; 0 = off).",
                                        0.0, 2.0)
        self.max_fillet_length = declare(self, "max_fillet_length_m", MAX_FILLET_LENGTH_M, "A blob longer along the "
                                         "flow than this is split into the fillets touching end to end in it (m; 0 = "
                                         "off).", 0.0, 2.0)
        self.max_fillet_area = declare(self, "max_fillet_area_m2", MAX_FILLET_AREA_M2, "A blob wider than "
                                       "max_fillet_width_m that covers more belt than this is surely fillets side by "
                                       "side, split however little their heights part them (m²; 0 = off).", 0.0, 1.0)
        self.depth_unit = declare(self, "depth_unit_m", DEPTH_UNIT_M, "One step of a 16UC1 depth image (m; REP "
                                  "118: 0.001, millimetres).", 1e-5, 0.01)
        self.camera_height = declare(self, "camera_height_m", TOP_CAMERA_HEIGHT_M,
                                     "Top camera height above the belt (m), part of its extrinsic calibration.",
                                     0.05, 10.0)
        max_unseen = declare(self, "max_unseen_frames", 15, "A track ends after this many frames unseen.", 1, 1000)
        max_distance = declare(self, "max_distance_px", 40.0, "Largest centroid jump matched frame to frame (px).",
                               1.0, 1000.0)
        frames = declare(self, "background_frames", 5, "Empty-belt frames the background is learned from.", 1, 1000)
        self.publish_debug = declare(self, "publish_debug_image", False, "Publish /vision/debug_image (contours, "
                                     "ids, scores) for a person watching.")
        self.background = BackgroundModel(frames)
        self.tracker_options = dict(max_distance_px=max_distance, max_unseen=max_unseen)
        self.tracker: CentroidTracker | None = None
        self.belt_view: BeltView | None = None
        """The camera's frames as the vision works on them (woody_vision.belt_view), once camera_info is known."""
        self.mount_watch = MountWatch(self)
        self.mount_from_tf = False
        self.checker = FrameChecker(self.get_logger())
        self.sim_time = SimTimeWatch()
        self.clock_jumps = watch_clock(self, self.sim_time, self.restart)
        self.latest_color: Image | None = None
        self.scores: dict[int, str] = {}
        self.info_size: tuple[int, int] | None = None
        self.pairing = self._declare_pairing()
        self.without_color = 0
        self.frames = 0
        self.tracked = 0
        self._create_interfaces()
        self.diagnostics = DiagnosticsPublisher(self, self.health)

    def _declare_segmentation(self) -> SegmentationParams:
        """The segmentation's parameters (woody_vision.segmentation.SegmentationParams), declared with its
        defaults."""
        defaults = SegmentationParams()
        return SegmentationParams(
            height_threshold_m=declare(self, "height_threshold_m", defaults.height_threshold_m, "Height above the "
                                       "belt background that counts as fillet (m).", 0.0005, 0.1),
            min_area_px=declare(self, "min_area_px", defaults.min_area_px, "Blobs smaller than this are dropped "
                                "(px).", 1, 100000),
            fill_invalid_px=declare(self, "fill_invalid_px", defaults.fill_invalid_px, "Pixels without depth take "
                                    "the mean height of the valid ones within this radius (px; 0 = off; 4 for a "
                                    "real camera).", 0, 50),
            median_px=declare(self, "median_px", defaults.median_px, "Median filter of the height map: 0 (off), 3 "
                              "or 5 (a noisy real camera).", 0, 5),
            blur_px=declare(self, "blur_px", defaults.blur_px, "Gaussian sigma smoothing the height map after the "
                            "median (px; 0 = off; 1.0 for a real camera).", 0.0, 20.0),
            color_threshold=declare(self, "color_threshold", defaults.color_threshold, "Outline from the registered "
                                    "colour image: a pixel near the depth mask whose colour differs from the empty "
                                    "belt's by more than this is fillet (8-bit levels; 0 = off; 20 for a real "
                                    "camera).", 0.0, 255.0),
            color_search_px=declare(self, "color_search_px", defaults.color_search_px, "Colour refines the outline "
                                    "only this close to the depth mask (px).", 0, 100),
            split_by_tracks=declare(self, "split_by_tracks", defaults.split_by_tracks, "Split a blob holding several "
                                    "tracked fillets (side by side, or a fillet and the lane-mate hanging ahead) "
                                    "where the tracker predicts them: fewer unscored fillets at the edge of a "
                                    "crowded line (docs/results.md)."),
            height_core_floor=declare(self, "height_core_floor", defaults.height_core_floor, "A blob wider than "
                                      f"max_fillet_width_m is split at its thick middles, cut at {HEIGHT_CORE_RATIO:g}"
                                      " x its height and lower down to this: lower splits a thin fillet from a thick "
                                      "one, fewer unscored, more woody ones passed (docs/results.md).", 0.3,
                                      HEIGHT_CORE_RATIO),
        )

    def _declare_pairing(self) -> FramePairing | None:
        """How colour frames pair with depth frames, or None when the outline comes from depth only."""
        sync = declare(self, "color_sync_tolerance_s", 0.0, "With color_threshold: a depth frame takes the colour "
                       "frame nearest its stamp within this (s); 0 = half the depth stream's frame interval, measured "
                       "(median of its recent stamp steps), so it fits a camera of any rate.", 0.0, 1.0)
        wait = declare(self, "color_wait_frames", HELD_DEPTH_FRAMES, "With color_threshold: depth frames that wait "
                       "for a late colour frame at most (a driver whose colour lags depth by N frames needs N).", 1,
                       MAX_HELD_DEPTH_FRAMES)
        return FramePairing(sync, wait) if self.params.color_threshold else None

    def _create_interfaces(self) -> None:
        """The tracks (and debug image) publisher and the camera, reset and verdict subscriptions."""
        sensor = declare_image_qos(self)
        self.tracks_pub = self.create_publisher(FilletTrackArray, topics.TRACKS,
                                                QoSProfile(depth=topics.TRACKS_QUEUE_DEPTH))
        self.debug_pub = self.create_publisher(Image, "vision/debug_image", 5) if self.publish_debug else None
        self.create_subscription(CameraInfo, topics.TOP_DEPTH_INFO, self.on_camera_info, sensor)
        self.create_subscription(Image, topics.TOP_DEPTH_IMAGE, self.on_depth, sensor)
        self.create_subscription(Empty, "~/reset_background", self.on_reset, 1)
        if self.publish_debug or self.params.color_threshold:
            self.create_subscription(Image, topics.TOP_COLOR_IMAGE, self.on_color, sensor)
        if self.publish_debug:
            self.create_subscription(FilletVerdict, topics.VERDICTS, self.on_verdict, 50)

    def health(self) -> Health:
        """No camera_info or no frames is an error (nothing is tracked); skipped frames are warnings."""
        values = {"depth frames": self.frames, "tracks in the latest frame": self.tracked,
                  "frames skipped (bad or mismatched)": self.checker.rejected,
                  "depth frames without their colour frame": self.without_color,
                  "colour/depth pairs dropped": self.pairing.dropped if self.pairing else 0,
                  "background learnt": self.background.ready}
        if self.tracker is None or not self.frames:
            what = topics.TOP_DEPTH_INFO if self.tracker is None else topics.TOP_DEPTH_IMAGE
            return Health(ERROR, f"waiting for {what}", values)
        skipped = self.checker.rejected + self.without_color
        return Health(WARN if skipped else OK, f"{self.frames} depth frames, {skipped} skipped", values)

    def on_camera_info(self, info: CameraInfo) -> None:
        if info.k[0] <= 0 or (self.tracker is not None and self.mount_from_tf):
            return
        pose = self.mount_watch.pose(info.header.frame_id)
        if self.tracker is not None and pose is None:
            return
        self.mount_from_tf = pose is not None
        source = f"tf_static {self.mount_watch.belt_frame} -> {info.header.frame_id}" if pose is not None else None
        try:
            self.belt_view = BeltView(CameraModel.of(info), pose or straight_down_pose(self.camera_height))
        except ValueError as exc:
            self.get_logger().error(f"camera_info {info.header.frame_id}: {exc}; no frame is segmented",
                                    throttle_duration_sec=30.0)
            return
        height = self.belt_view.height_m
        layout = LaneLayout(tuple(info.k), height, self.lanes, self.lane_pitch)
        self.params = self.params.for_camera(info.k, height, self.max_fillet_width, self.max_fillet_length,
                                             self.max_fillet_area)
        if self.tracker is None:
            self.tracker = CentroidTracker(lane_layout=layout, **self.tracker_options)
        else:  # tf_static came after the first camera_info: its mount from now on
            self.tracker.lane_layout = layout
        self.info_size = (info.width, info.height)
        view = "as it is" if self.belt_view.identity else "resampled into the belt view (woody_vision.belt_view)"
        self.get_logger().info(f"calibration received: fx={info.k[0]:.1f}, {info.width}x{info.height}; camera "
                               f"height {height:.3f} m from {source or 'the parameters'}; frames used {view}")

    def on_reset(self, _msg: Empty) -> None:
        self.background.reset()
        self.checker.reset()
        self.get_logger().info("background reset: relearning from the next frames")

    def on_color(self, msg: Image) -> None:
        stamp = stamp_to_seconds(msg.header.stamp)
        if self.sim_time.went_back("color", stamp):  # colour comes before its depth frame: forget before keeping it
            self.restart(f"{topics.TOP_COLOR_IMAGE} stamp went back to {stamp:.2f} s")
        self.latest_color = msg
        if self.pairing is not None:
            for pair in self.pairing.add_color(stamp_to_nanoseconds(msg.header.stamp), msg):
                self._segment(pair)

    def on_verdict(self, msg: FilletVerdict) -> None:
        verdict = {FilletVerdict.CLASS_NORMAL: "normal", FilletVerdict.CLASS_WOODY: "woody"}
        self.scores[msg.fillet_id] = f"phi {msg.phi:.1f} {verdict.get(msg.classification, 'unscored')}"
        while len(self.scores) > 200:  # only fillets still in view need their score
            self.scores.pop(next(iter(self.scores)))

    def on_depth(self, msg: Image) -> None:
        self.frames += 1
        stamp = stamp_to_seconds(msg.header.stamp)
        if self.sim_time.went_back("depth", stamp):
            self.restart(f"{topics.TOP_DEPTH_IMAGE} stamp went back to {stamp:.2f} s")
        try:
            depth = depth_metres(msg, self.depth_unit)
            self.checker.check(msg, depth.shape)
            self._check_calibration_size(msg)
        except FrameError as exc:
            self.checker.reject(str(exc))
            return
        if self.checker.restarted:
            self.restart(f"the depth image size changed to {msg.width}x{msg.height}")
        if self.pairing is None:  # depth only: never waits for colour
            self._segment(Pair((msg, depth), None))
            return
        for pair in self.pairing.add_depth(stamp_to_nanoseconds(msg.header.stamp), (msg, depth)):
            self._segment(pair)

    def restart(self, why: str) -> None:
        """The camera restarted or sim time went back: relearn the background, drop every track and held frame."""
        self.background.reset()
        self.checker.reset()
        if self.pairing is not None:
            self.pairing.clear()
        self.scores.clear()
        if self.tracker is not None:
            self.tracker.reset()
        self.get_logger().warning(f"camera restarted or sim time went back ({why}): relearning the background, "
                                  "tracks start over")

    def _segment(self, pair: Pair) -> None:
        """Segment and track one depth frame (with its colour frame, when the outline comes from colour)."""
        msg, depth = pair.depth
        color = self._color_of(pair, depth.shape)
        if self.belt_view is not None:
            depth, color = self.belt_view.depth(depth), self.belt_view.color(color)
        out = FilletTrackArray(header=msg.header, image_width=msg.width, image_height=msg.height)
        if self.pairing is not None and color is None:
            self.tracks_pub.publish(out)  # answered (a paced line_sim waits for it), but nothing tracked
            return
        if not self.background.ready or self.tracker is None:
            if not self.background.ready:
                self.background.add(depth, color)
            else:
                self.checker.reject("no camera_info received yet on /top_camera/depth/camera_info; frame skipped")
            self.tracks_pub.publish(out)  # every depth frame is answered: a paced line_sim waits for it
            return
        stamp = stamp_to_seconds(msg.header.stamp)
        blobs = segment_depth(depth, self.background.depth, self.params, color, self.background.color,
                              self.tracker.predicted_outlines(stamp))
        update = self.tracker.update(blobs, stamp)
        out.ended_ids = [t.track_id for t in update.ended]
        layout = self.tracker.lane_layout
        for track in update.active:
            blob = track.blob
            u, v, w, h = blob.bbox
            belt = belt_outline(blob.contour, depth, layout.k, layout.camera_height_m)
            out.tracks.append(FilletTrack(
                id=track.track_id, lane=max(track.lane, 0), centroid_u=float(blob.centroid[0]),
                centroid_v=float(blob.centroid[1]), bbox_u=u, bbox_v=v, bbox_width=w, bbox_height=h,
                area=float(blob.area_px), mean_height=float(blob.mean_height_m), age=track.age, unseen=track.unseen,
                contour_uv=array.array("i", blob.contour.astype(np.int32).tobytes()),
                belt_contour_uv=array.array("i", belt.tobytes())))
        self.tracks_pub.publish(out)
        self.tracked = len(out.tracks)
        if self.debug_pub is not None:
            self._publish_debug(msg, update.active, pair.color)

    def _color_of(self, pair: Pair, shape: tuple[int, ...]) -> np.ndarray | None:
        """The pair's colour frame at the depth frame's size, or None (a throttled warning) without one."""
        if self.pairing is None:
            return None
        try:
            if pair.color is not None:
                return match_size(color_rgb(pair.color), shape[0], shape[1])
            reason = pair.reason
        except FrameError as exc:
            reason = str(exc)
        self.without_color += 1
        self.get_logger().warning(f"{reason}: depth frame skipped ({self.without_color} so far)",
                                  throttle_duration_sec=5.0)
        return None

    def _check_calibration_size(self, msg: Image) -> None:
        """Refuse depth frames of another size than the camera_info their K belongs to."""
        if self.info_size is not None and self.info_size != (msg.width, msg.height):
            raise FrameError(f"depth image {msg.width}x{msg.height} does not match its camera_info "
                             f"{self.info_size[0]}x{self.info_size[1]}: K would be wrong; frame skipped")

    def _debug_canvas(self, depth_msg: Image, paired: Image | None) -> np.ndarray:
        """The depth frame's colour frame (its pair with the colour outline, else the latest one of the same stamp)
        at the depth image's size, or black when there is none."""
        blank = np.zeros((depth_msg.height, depth_msg.width, 3), np.uint8)
        color = paired if paired is not None else self.latest_color
        if color is None or (paired is None and color.header.stamp != depth_msg.header.stamp):
            return blank
        try:
            canvas = match_size(color_rgb(color), depth_msg.height, depth_msg.width)
            return (self.belt_view.color(canvas) if self.belt_view is not None else canvas).copy()
        except FrameError as exc:
            self.checker.reject(f"debug image: {exc}")
            return blank

    def _publish_debug(self, depth_msg: Image, tracks, paired: Image | None) -> None:
        canvas = self._debug_canvas(depth_msg, paired)
        for track in tracks:
            colour = (0, 255, 0) if track.unseen == 0 else (255, 160, 0)
            cv2.polylines(canvas, [track.blob.contour.reshape(-1, 1, 2)], True, colour, 1)
            score = self.scores.get(track.track_id)
            label = f"{track.track_id} L{track.lane}" + (f" {score}" if score is not None else "")
            u, v = (int(c) for c in track.blob.centroid)
            cv2.putText(canvas, label, (u - 20, v), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 0), 1)
        self.debug_pub.publish(serialized_image(canvas, "rgb8", depth_msg.header))

    def close(self) -> None:
        print(f"[segmenter] {self.frames} depth frames received, {self.checker.rejected} rejected"
              + (self._pairing_summary() if self.pairing is not None else ""), flush=True)

    def _pairing_summary(self) -> str:
        tolerance = self.pairing.tolerance_ns
        within = "not measured" if tolerance is None else f"±{tolerance / 1e6:.1f} ms"
        return (f", {self.without_color} skipped without their colour frame ({self.pairing.dropped} without one "
                f"within the tolerance, {within})")


def main(args: list[str] | None = None) -> None:
    cv2.setNumThreads(1)  # per-frame work is small: OpenCV's thread pool costs more than it gains on 2 cores
    sys.exit(run_node("segmenter", Segmenter, args))


if __name__ == "__main__":
    main()
