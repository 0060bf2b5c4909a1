"""grader: tracks and side-view frames in, one verdict per fillet out (/grading/verdicts).

The watched lane's side-view metrics go out on their own (/grading/side_metrics,
one per watched-lane fillet, paired by fillet id) when the fillet's side
passage ends: a verdict never waits for the side camera, so the gate gets it
as early for the watched lane as for any other.

Thin adapter over woody_vision.grader_core. The roller edge row comes from
the top camera's calibration (K from camera_info, plus the camera height and
the edge offset from its optical axis as parameters), never from a pixel
constant; the side view's roller axle and radius are parameters of that
camera's calibration. When sim time goes back (/clock, the track stamps or
the side frames' stamps; a replay started again, a restarted line) it forgets
every fillet in progress, with one log line, so a second pass is graded like
the first.

The Φ threshold and the line's cuts are parameters with plain defaults: the
params file the node is started with (`woody run` passes the calibration) is
their source; a grader started without them reads the resolved calibration
once, before declaring (woody_common.ros_params.calibrated_defaults), and
never inside a default. Nothing here imports the simulator, so the node runs
on a vision-only host.
"""

from __future__ import annotations

import math
import sys
import time
from collections import deque

import cv2
import numpy as np
from foxglove_msgs.msg import ImageAnnotations
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import CameraInfo, Image

from woody_common import topics
from woody_common.diagnostics import ERROR, GRADED_UP_TO, OK, WARN, DiagnosticsPublisher, Health
from woody_common.line import (
    LANES,
    MAX_LANES,
    SIDE_AXLE_PX,
    SIDE_ROLLER_RADIUS_PX,
    TOP_CAMERA_HEIGHT_M,
    TOP_EDGE_OFFSET_M,
    watched_lane,
)
from woody_common.ros_params import calibrated_defaults, declare, run_node
from woody_common.stamps import seconds_to_stamp, stamp_to_seconds
from woody_msgs.msg import FilletTrackArray, FilletVerdict, SideMetrics
from woody_vision import side_view
from woody_vision.annotations import image_annotations
from woody_vision.camera_model import edge_row
from woody_vision.frame_checks import FrameChecker, FrameError, SimTimeWatch, watch_clock
from woody_vision.grader_core import (
    DEFAULT_SIDE_WAIT_S,
    SCORE_LINE,
    SCORE_PAPER,
    FilletGrader,
    GradedFillet,
    SideResult,
    TrackObservation,
    check_score,
)
from woody_vision.grading import THRESHOLD_RANGE, Cut, FittedRange, GradingRules
from woody_vision.image_encodings import color_rgb
from woody_vision.image_qos import declare_image_qos
from woody_vision.mount_watch import MountWatch
from woody_vision.overlays import FRAME, Overlay, outline, verdict_overlays
from woody_vision.result_qos import results_qos
from woody_vision.shape_score import LINE_OVERHANG_FRACTION, TIP_WIDTH_RATIO, W1, W2
from woody_vision.side_view import SidePassageTracker
from woody_vision.verdict_message import verdict_message

SIDE_QUEUE_FRAMES = 60
"""Side frames queued for the grader (1 s of a 60 Hz camera, ~120 MB at most): a line running faster than real
time sends a passage's frames in a burst, and a frame pushed out of a short queue is a passage measured without
its NMDM."""
EARLY_TRACKS = 900
"""Track messages kept while camera_info has not arrived yet (30 s of a 30 Hz camera)."""

class Grader(Node):
    """Scores Φ per track and publishes verdicts; measures the watched lane's fillets from the side."""

    def __init__(self) -> None:
        super().__init__("grader")
        self.rules = self._declare_rules()
        self.camera_height = declare(self, "camera_height_m", TOP_CAMERA_HEIGHT_M,
                                     "Top camera height above the belt (m).", 0.05, 10.0)
        self.edge_offset = declare(self, "roller_edge_offset_m", TOP_EDGE_OFFSET_M,
                                   "Distance from the top camera's optical axis to the roller edge along the flow (m).",
                                   -5.0, 5.0)
        self.evaluator_options = dict(
            w1=declare(self, "w1", W1, "Weight of the Hu-moment term of Φ.", 0.0, 1e6),
            w2=declare(self, "w2", W2, "Weight of the solidity term of Φ.", 0.0, 1e6),
            tip_ratio=declare(self, "tip_ratio", TIP_WIDTH_RATIO, "The reference's narrow leading end is cut up to the "
                              "first line at least this fraction of the maximum body width.", 0.01, 0.99),
            line_fraction=declare(self, "line_fraction", LINE_OVERHANG_FRACTION, "line_phi is Φ_t where the rigid "
                                  "overhang is this fraction of the body length.", 0.1, 0.9),
        )
        self.mount_watch = MountWatch(self)
        self.first_info_at = 0.0
        self.side = self._declare_side_view()
        self.core: FilletGrader | None = None
        self.early_tracks: deque = deque(maxlen=EARLY_TRACKS)
        """Track messages received before the first camera_info, graded as soon as it arrives."""
        side_view.warm_up()  # before any subscription: the first passage is measured whole, never while compiling
        self.side_checker = FrameChecker(self.get_logger())
        self.sim_time = SimTimeWatch()
        self.clock_jumps = watch_clock(self, self.sim_time, self.forget)
        self.published = 0
        self.unscored = 0
        self.side_published = 0
        self.graded_up_to = 0.0
        annotate = declare(self, "publish_annotations", True, "Publish grading/annotations (foxglove_msgs/"
                           "ImageAnnotations, one per top frame: each track's outline coloured by its state with a "
                           "label of id, lane and Φ_t; at its verdict the reference outline and the outline at the "
                           "measuring point, labelled with score and cut) for Foxglove and `woody report`.")
        self.labels: dict[int, str] = {}

        sensor = declare_image_qos(self)
        self.verdict_pub = self.create_publisher(FilletVerdict, topics.VERDICTS, results_qos())
        self.side_pub = self.create_publisher(SideMetrics, topics.SIDE_METRICS, results_qos()) if self.side else None
        self.annotation_pub = (self.create_publisher(ImageAnnotations, topics.ANNOTATIONS, 50) if annotate
                               else None)
        self.create_subscription(CameraInfo, topics.TOP_DEPTH_INFO, self.on_camera_info, sensor)
        self.create_subscription(FilletTrackArray, topics.TRACKS, self.on_tracks,
                                 QoSProfile(depth=topics.TRACKS_QUEUE_DEPTH))
        if self.side is not None:
            side_queue = QoSProfile(history=sensor.history, depth=SIDE_QUEUE_FRAMES, reliability=sensor.reliability)
            self.create_subscription(Image, topics.SIDE_IMAGE, self.on_side_image, side_queue)
        self.create_timer(0.1, self.on_timer)
        self.frame_id = ""
        self.side_frame_id = ""
        self.diagnostics = DiagnosticsPublisher(self, self.health)

    def health(self) -> Health:
        """Waiting for camera_info is an error (nothing is graded); unscored fillets (diverted) and rejected
        side frames are warnings."""
        values = {"verdicts": self.published, "unscored": self.unscored, "side metrics": self.side_published,
                  "tracks in progress": self.core.in_progress if self.core else 0,
                  "track messages waiting for camera_info": len(self.early_tracks),
                  "side frames rejected": self.side_checker.rejected, GRADED_UP_TO: f"{self.graded_up_to:.3f}"}
        if self.core is None:
            return Health(ERROR, f"waiting for camera_info on {topics.TOP_DEPTH_INFO}", values)
        line = f"{self.published} verdicts, {self.unscored} unscored"
        return Health(WARN if self.unscored or self.side_checker.rejected else OK, line, values)

    def _declare_side_view(self) -> SidePassageTracker | None:
        """Declare the lanes and the side view's parameters; its passage tracker (None with the side view off)."""
        lanes = declare(self, "lanes", LANES, "Lanes across the belt.", 1, MAX_LANES)
        side_lane = declare(self, "side_lane", -1, "Lane the side camera watches (-1 = centre lane).", -1,
                            MAX_LANES - 1)
        enabled = declare(self, "use_side_view", True, "Measure NMDM/MDM/BE on the watched lane.")
        self.side_wait = declare(self, "side_wait_s", DEFAULT_SIDE_WAIT_S,
                                 "Longest a watched-lane fillet's side metrics wait for its side passage to "
                                 "end (sim s, by the side frames' stamps); then they are published absent, with the "
                                 "reason.", 0.0, 10.0)
        options = dict(
            axle_px=(declare(self, "roller_axle_u", SIDE_AXLE_PX[0], "Roller axle column in the side image (px).",
                             -1e4, 1e4),
                     declare(self, "roller_axle_v", SIDE_AXLE_PX[1], "Roller axle row in the side image (px).",
                             -1e4, 1e4)),
            roller_radius_px=declare(self, "roller_radius_px", SIDE_ROLLER_RADIUS_PX,
                                     "Roller radius in the side image (px).", 1.0, 1e4),
        )
        if side_lane >= lanes:
            raise ValueError(f"side_lane {side_lane} is not a lane (0..{lanes - 1})")
        self.watched_lane = watched_lane(lanes, side_lane)
        return SidePassageTracker(**options) if enabled else None

    def _declare_rules(self) -> GradingRules:
        """Declare ``score``, the paper's threshold and the line's three cuts; the rules the score uses."""
        defaults = calibrated_defaults(self, "grader")
        self.score = check_score(declare(self, "score", SCORE_LINE, "What the verdict grades: line (line_phi "
                                         "against cuts that follow the measured speed and leading end; robust on a "
                                         "messy line) or paper (the paper's Φ against the single threshold; no "
                                         "grade)."))
        paper = declare(self, "threshold", defaults["threshold"], "With score paper: Φ below this is woody "
                        "(stiff fillets deform less); the default is the calibrated one.", *THRESHOLD_RANGE)
        cuts = [Cut.of(declare(self, name, defaults[name], text)) for name, text in (
            ("line_threshold", "With score line: the reject cut on line_phi, [base at 100 FPM, narrow end first, "
             "straight, 0.19 m long; d ln(cut)/d speed per m/s; ln offset blunt end first; d ln(cut)/d turn per "
             "degree; d ln(cut)/d length per m]; the default is the calibrated one."),
            ("severe_threshold", "With score line: line_phi below this cut grades severe (same form)."))]
        fitted = FittedRange.of(declare(self, "fitted_range", defaults["fitted_range"], "The measured conditions "
                                        "the cuts were fitted on, [speed min, speed max (m/s), turn max (degrees), "
                                        "body length min, max (m)]: a fillet measured outside them is unscored with "
                                        "the reason (the gate diverts it); the default is the calibrated one."))
        outside = declare(self, "grade_outside_calibration", False, "Grade fillets measured outside fitted_range "
                          "anyway, on extrapolated cuts (at 400 FPM those pass every woody fillet).")
        self.fitted_range = None if outside else fitted
        return GradingRules(paper) if self.score == SCORE_PAPER else GradingRules(*cuts)

    def on_camera_info(self, info: CameraInfo) -> None:
        if self.core is None and info.k[0] > 0:
            now = time.monotonic()
            self.first_info_at = self.first_info_at or now
            height, offset, source = self.mount_watch.geometry(info.header.frame_id, self.camera_height,
                                                               self.edge_offset)
            if source is None and self.mount_watch.waiting(self.first_info_at, now):
                return  # tracks wait in early_tracks
            row = edge_row(tuple(info.k), height, offset)
            self.core = FilletGrader(row, self.rules, self.watched_lane if self.side else None, self.side_wait,
                                     self.evaluator_options, info.k[4] / height, self.score, self.fitted_range)
            self.get_logger().info(f"roller edge at image row {row:.1f} (camera_info K; camera height {height:.3f} m "
                                   f"and edge offset {offset:.3f} m from {source or 'the parameters'})")
            early, self.early_tracks = self.early_tracks, deque()
            for msg in early:  # tracks that arrived before camera_info (discovery order) are graded, not lost
                self.on_tracks(msg)

    def on_tracks(self, msg: FilletTrackArray) -> None:
        if self.core is None:
            if msg.tracks or msg.ended_ids:  # empty arrays (the segmenter learning its background) lose nothing
                if len(self.early_tracks) == self.early_tracks.maxlen:
                    self.side_checker.reject("no camera_info on top_camera/depth/camera_info yet; oldest tracks "
                                             "dropped")
                self.early_tracks.append(msg)
            return
        self.frame_id = msg.header.frame_id
        stamp = stamp_to_seconds(msg.header.stamp)
        if self.sim_time.went_back("tracks", stamp):
            self.forget(f"{topics.TRACKS} stamp went back to {stamp:.2f} s")
        usable = [t for t in msg.tracks if _outline_ok(t.contour_uv) and _outline_ok(t.belt_contour_uv)]
        if len(usable) < len(msg.tracks):
            bad = sorted(set(t.id for t in msg.tracks) - set(t.id for t in usable))
            self.side_checker.reject(f"tracks {bad}: contour_uv or belt_contour_uv not u, v pairs of at least 3 "
                                     "points; those skipped")
        tracks = [TrackObservation(t.id, t.lane, _points(t.belt_contour_uv), t.unseen, _points(t.contour_uv))
                  for t in usable]
        graded = self.core.on_tracks(stamp, tracks, msg.ended_ids)
        self._publish(graded)
        self._publish_side(self.core.release(stamp))
        self.graded_up_to = stamp
        if self.annotation_pub is not None:
            overlays = [Overlay(t.id, t.lane, self.labels.get(t.id, "pending"), FRAME, stamp,
                                outline(_points(t.contour_uv)), phi=self.core.frame_phi(t.id, stamp)) for t in usable]
            overlays += [overlay for fillet in graded for overlay in verdict_overlays(fillet)]
            self.annotation_pub.publish(image_annotations(overlays, stamp))

    def on_side_image(self, msg: Image) -> None:
        stamp = stamp_to_seconds(msg.header.stamp)
        if self.sim_time.went_back("side", stamp):
            self.forget(f"{topics.SIDE_IMAGE} stamp went back to {stamp:.2f} s")
        try:
            rgb = color_rgb(msg)
            self.side_checker.check(msg, rgb.shape)
        except FrameError as exc:
            self.side_checker.reject(f"side camera: {exc}")
            return
        if self.side_checker.restarted:  # the size changed
            self.side.reset()
        self.side_frame_id = msg.header.frame_id
        measurements = self.side.update(rgb, stamp)
        if self.core is not None:
            for measurement in measurements:
                self._publish_side(self.core.on_side(measurement))
            self._publish_side(self.core.side_seen(stamp))

    def forget(self, why: str) -> None:
        """Sim time went back: drop every fillet in progress (tracks, side results to come, side passages)."""
        tracks, held = self.core.reset() if self.core is not None else (0, 0)
        if self.side is not None:
            self.side.reset()
            self.side_checker.reset()
        self.labels.clear()
        self.get_logger().warning(f"sim time went back ({why}): forgot {tracks} tracks in progress and {held} "
                                  "side results to come; grading starts over")

    def on_timer(self) -> None:
        now = self.get_clock().now().nanoseconds * 1e-9
        if self.core is not None and self.sim_time.clock_current(now):
            self._publish_side(self.core.release(now))

    def _publish(self, graded: list[GradedFillet]) -> None:
        for fillet in graded:
            self.verdict_pub.publish(verdict_message(fillet, self.rules, self.frame_id, self.core.now))
            self.published += 1
            self.unscored += fillet.label == "unscored"
            self.labels[fillet.fillet_id] = fillet.label
            while len(self.labels) > 200:  # only fillets still in view are drawn
                self.labels.pop(next(iter(self.labels)))

    def _publish_side(self, results: list[SideResult]) -> None:
        for result in results:
            self.side_pub.publish(self.side_msg(result))
            self.side_published += 1

    def side_msg(self, result: SideResult) -> SideMetrics:
        side, nan = result.side, math.nan
        msg = SideMetrics(fillet_id=result.fillet_id, lane=max(result.lane, 0), measured=side is not None,
                          reason=result.reason, nmdm=side.nmdm if side else nan,
                          mdm=side.mdm_min_px if side else nan, be=side.be if side else nan)
        msg.header.stamp = seconds_to_stamp(result.stamp)
        msg.header.frame_id = self.side_frame_id
        return msg

    def close(self) -> None:
        pieces, taken = (self.core.fragments, self.core.taken_over) if self.core is not None else (0, 0)
        print(f"[grader] published {self.published} verdicts and {self.side_published} side results; {pieces} "
              f"tracks were pieces split off a fillet (no verdict); {taken} tracks carried on a fillet its own "
              "track had lost", flush=True)


def _outline_ok(flat) -> bool:
    """A flat u, v array of at least three points."""
    return len(flat) >= 6 and len(flat) % 2 == 0


def _points(flat) -> np.ndarray:
    return np.frombuffer(flat, np.int32).reshape(-1, 2)


def main(args: list[str] | None = None) -> None:
    cv2.setNumThreads(1)  # per-frame work is small: OpenCV's thread pool costs more than it gains on 2 cores
    sys.exit(run_node("grader", Grader, args))


if __name__ == "__main__":
    main()
