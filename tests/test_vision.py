"""Top-down vision on synthetic frames with known geometry: segmentation, tracking, frame checks, grading rules.

Frames come from woody_vision.synthetic (a nadir pinhole camera over the belt
end); where a test needs a shape whose width profile or bending is known
analytically, it draws the polygon itself.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from woody_common.line import TOP_CAMERA_HEIGHT_M
from woody_vision.camera_model import LaneLayout, lane_center_u
from woody_vision.frame_checks import RESIZE_CONFIRM_FRAMES, FrameChecker, FrameError, image_to_array
from woody_vision.grading import GradingRules
from woody_vision.segmentation import (
    DEFAULT_HEIGHT_THRESHOLD_M,
    REAL_CAMERA_FILTERS,
    BackgroundModel,
    Blob,
    SegmentationParams,
    height_map,
    segment_depth,
)
from woody_vision.synthetic import (
    DEFAULT_TOP_K,
    TopFillet,
    TopScene,
)
from woody_vision.tracking import CentroidTracker, TrackUpdate

FPS = 30.0
LAYOUT3 = LaneLayout(DEFAULT_TOP_K, TOP_CAMERA_HEIGHT_M, 3, 0.16)


# ----------------------------------------------------------------- helpers


def segment(fillets, t: float = 0.0, params: SegmentationParams | None = None) -> list[Blob]:
    scene = TopScene(fillets)
    return segment_depth(scene.render(t)[1], scene.background_depth(), params or SegmentationParams())


def mask_components(fillets, t: float = 0.0) -> int:
    """Connected components of the thresholded, opened mask: >1 fillet per component means they touch."""
    scene = TopScene(fillets)
    height = height_map(scene.render(t)[1], scene.background_depth())
    mask = cv2.morphologyEx((height > DEFAULT_HEIGHT_THRESHOLD_M).astype(np.uint8), cv2.MORPH_OPEN,
                            cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5)))
    count, _, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    return sum(1 for i in range(1, count) if stats[i, cv2.CC_STAT_AREA] >= 500)


def fillet_masks(fillets, t: float) -> list[np.ndarray]:
    """Each fillet rendered alone: its own pixel mask (the ground truth for matching blobs)."""
    out = []
    for fillet in fillets:
        scene = TopScene([fillet])
        out.append((scene.background_depth() - scene.render(t)[1]) > DEFAULT_HEIGHT_THRESHOLD_M)
    return out


def owner(blob: Blob, masks: list[np.ndarray]) -> int:
    """Index of the fillet whose own pixels cover most of the blob (-1 if none covers half of it)."""
    filled = np.zeros(masks[0].shape, np.uint8)
    cv2.fillPoly(filled, [blob.contour.reshape(-1, 1, 2)], 1)
    overlaps = [int(np.count_nonzero(filled.astype(bool) & m)) for m in masks]
    best = int(np.argmax(overlaps))
    return best if overlaps[best] >= 0.5 * blob.area_px else -1


def square_blob(u: float, v: float, half: int = 15) -> Blob:
    contour = np.array([[u - half, v - half], [u + half, v - half], [u + half, v + half], [u - half, v + half]],
                       np.int32)
    return Blob(contour=contour, centroid=(float(u), float(v)), area_px=(2 * half) ** 2,
                bbox=(int(u - half), int(v - half), 2 * half, 2 * half), mean_height_m=0.02)


def polygon_contour(points: np.ndarray) -> np.ndarray:
    return np.round(np.asarray(points, float)).astype(np.int32)


def moments_centroid_v(contour: np.ndarray) -> float:
    m = cv2.moments(contour)
    return m["m01"] / m["m00"]


# ------------------------------------------------------------ segmentation

L, W = 0.19, 0.095


@pytest.mark.parametrize("overlap_m", [0.005, 0.01])
@pytest.mark.parametrize("lead_m", [-0.2, 0.0])
def test_tip_to_tail_touching_fillets_split_at_their_contact(overlap_m, lead_m):
    """A follower touching its leader in the same lane: two blobs, each matching the fillet drawn alone."""
    fillets = [TopFillet(lead_m=lead_m, across_m=0.0), TopFillet(lead_m=lead_m - L + overlap_m, across_m=0.0)]
    t = 0.1 if lead_m == 0.0 else 0.0
    assert mask_components(fillets, t) == 1, "precondition: the two fillets form one connected component"
    blobs = segment(fillets, t)
    singles = [segment([f], t)[0] for f in fillets]
    assert len(blobs) == 2
    for single in singles:
        match = min(blobs, key=lambda b: math.dist(b.centroid, single.centroid))
        assert math.dist(match.centroid, single.centroid) < 1.5
        assert abs(match.area_px - single.area_px) < 0.03 * single.area_px


@pytest.mark.parametrize("overlap_m,stagger_m", [(0.0, 0.0), (0.004, 0.0), (0.008, 0.01), (0.002, 0.03)])
def test_side_by_side_fillets_across_lanes_split_into_two_blobs_and_tracks(overlap_m, stagger_m):
    """Neighbours in two lanes touching along their length (one distance core, two end notches)."""
    pitch = W - overlap_m
    layout = LaneLayout(DEFAULT_TOP_K, TOP_CAMERA_HEIGHT_M, 2, pitch)
    fillets = [TopFillet(lead_m=-0.25, across_m=pitch / 2), TopFillet(lead_m=-0.25 - stagger_m, across_m=-pitch / 2)]
    assert mask_components(fillets) == 1, "precondition: the two fillets form one connected component"
    singles = [segment([f])[0] for f in fillets]
    blobs = segment(fillets)
    assert len(blobs) == 2
    for single in singles:
        match = min(blobs, key=lambda b: math.dist(b.centroid, single.centroid))
        assert math.dist(match.centroid, single.centroid) < 2.0
        assert abs(match.area_px - single.area_px) < 0.06 * single.area_px

    tracker = CentroidTracker(lane_layout=layout)
    scene = TopScene(fillets)
    ids_per_lane: dict[int, set[int]] = {0: set(), 1: set()}
    for i in range(8):
        update = tracker.update(segment_depth(scene.render(i / FPS)[1], scene.background_depth()))
        assert len(update.active) == 2 and not update.ended
        for track in update.active:
            ids_per_lane[track.lane].add(track.track_id)
    assert ids_per_lane == {0: {0}, 1: {1}} or ids_per_lane == {0: {1}, 1: {0}}


@pytest.mark.parametrize("mesh", [0, 1, 2])
def test_a_rigid_fillet_keeps_its_segmented_outline_as_it_passes_the_roller_edge(mesh):
    """Past the edge the background is the floor, so rim thinner than the height threshold, hidden on the belt,
    would appear there and grow the outline of a fillet that does not bend at all (the old Φ floor)."""
    from woody_sim.line_geometry import LineGeometry
    from woody_sim.rendering import LineRenderer, flat_poses, load_reference_visuals

    geometry = LineGeometry()
    visuals, offsets = load_reference_visuals(mesh, 40)
    renderer = LineRenderer(geometry, render_side=False)
    renderer.add_fillet(0, 1, visuals)
    background = renderer.render_top({})[1]

    def area(centre_x: float, params: SegmentationParams) -> int:
        depth = renderer.render_top({0: flat_poses(offsets, centre_x, geometry.lane_y(1))})[1]
        (blob,) = segment_depth(depth, background, params)
        return blob.area_px

    def growth(params: SegmentationParams) -> float:  # fully on the belt, then ~5 cm overhanging, still flat
        return area(-0.04, params) / area(-0.15, params) - 1.0

    assert abs(growth(SegmentationParams())) < 0.003
    assert growth(SegmentationParams(height_threshold_m=0.005)) > 0.005


def test_single_fillets_are_never_split_while_crossing_the_edge():
    rng = np.random.default_rng(4)
    for _ in range(8):
        fillet = TopFillet(lead_m=-0.15, across_m=rng.uniform(-0.3, 0.3), length_m=rng.uniform(0.17, 0.22),
                           width_m=rng.uniform(0.08, 0.11), thickness_m=rng.uniform(0.02, 0.035),
                           curvature_per_m=rng.uniform(0.0, 16.0), tip_rate_per_m=rng.uniform(6.0, 20.0))
        scene = TopScene([fillet])
        for i in range(0, 36, 3):
            assert len(segment_depth(scene.render(i / FPS)[1], scene.background_depth())) <= 1


def test_blob_geometry_matches_the_drawn_fillet():
    scene = TopScene([TopFillet(lead_m=-0.2, across_m=0.05)])
    (blob,) = segment_depth(scene.render(0.0)[1], scene.background_depth())
    intr = scene.intrinsics
    expected_u = intr.cx + intr.fx * 0.05 / (TOP_CAMERA_HEIGHT_M - 0.02)
    assert blob.centroid[0] == pytest.approx(expected_u, abs=1.0)
    u, v, w, h = blob.bbox
    assert (blob.contour[:, 0].min(), blob.contour[:, 1].min()) == (u, v)
    assert (blob.contour[:, 0].max(), blob.contour[:, 1].max()) == (u + w - 1, v + h - 1)
    assert 0.005 < blob.mean_height_m < 0.03


def test_small_specks_are_dropped():
    background = np.full((120, 160), 0.75, np.float32)
    depth = background.copy()
    depth[10:30, 10:30] = 0.72  # 400 px: below the 500 px minimum
    depth[50:100, 50:110] = 0.72  # 3000 px: kept
    blobs = segment_depth(depth, background)
    assert len(blobs) == 1 and blobs[0].area_px == pytest.approx(3000, abs=10)  # opening rounds the corners


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
def test_non_finite_depth_gives_no_blobs(value):
    background = TopScene([]).background_depth()
    assert segment_depth(np.full_like(background, value), background) == []
    depth = background.copy()
    depth[100:160, 200:300] = value  # a patch of bad returns is not a fillet
    assert segment_depth(depth, background) == []


def test_non_finite_pixels_inside_a_fillet_do_not_poison_it():
    background = np.full((200, 200), 0.75, np.float32)
    background[:5] = np.nan  # never-measured background pixels never rise
    depth = background.copy()
    depth[50:150, 50:150] = 0.72
    depth[90:95, 90:95] = np.nan
    depth[0:3, 0:100] = 0.1
    (blob,) = segment_depth(depth, background)
    assert blob.area_px == pytest.approx(100 * 100 - 25, abs=20)
    assert blob.mean_height_m == pytest.approx(0.03, abs=1e-6)


def test_holes_and_noise_of_a_real_camera_are_filled_and_smoothed_before_the_contour():
    rng = np.random.default_rng(0)
    background = np.full((200, 200), 0.75, np.float32)
    depth = background + rng.normal(0.0, 0.002, background.shape).astype(np.float32)
    depth[50:150, 50:150] -= 0.02
    depth[45:56, 90:101] = np.nan  # a hole across the top border
    depth[120:126, 145:151] = 0.0  # and one on the right border
    raw = segment_depth(depth, background)
    (clean,) = segment_depth(depth, background, SegmentationParams(**REAL_CAMERA_FILTERS))
    assert clean.area_px == pytest.approx(100 * 100, rel=0.05)  # the blur widens a 20 mm step by ~1 px a side
    hull = cv2.contourArea(cv2.convexHull(clean.contour))
    assert cv2.contourArea(clean.contour) / hull > 0.97  # no notches left by the holes
    assert sum(b.area_px for b in raw) < clean.area_px
    for bad in (dict(median_px=4), dict(blur_px=-1.0), dict(fill_invalid_px=-1)):
        with pytest.raises(ValueError):
            SegmentationParams(**bad)


def test_empty_frames_give_no_blobs():
    background = TopScene([]).background_depth()
    assert segment_depth(background.copy(), background) == []
    empty = np.zeros((0, 0), np.float32)
    assert segment_depth(empty, empty) == []
    assert segment_depth(np.zeros((0, 672), np.float32), np.zeros((0, 672), np.float32)) == []


def test_background_model_ignores_missing_returns():
    model = BackgroundModel(frames_needed=3)
    a = np.full((4, 4), 0.75, np.float32)
    b = a.copy()
    b[0, 0] = np.nan
    c = a.copy()
    c[0, 0] = np.inf
    c[1, 1] = np.nan
    assert not model.add(a) and not model.add(b)
    with pytest.raises(RuntimeError):
        _ = model.depth
    assert model.add(c)
    assert np.allclose(model.depth, 0.75)
    never = BackgroundModel(1)
    never.add(np.full((2, 2), np.nan, np.float32))
    assert np.isnan(never.depth).all()
    assert segment_depth(np.full((2, 2), 0.1, np.float32), never.depth) == []
    with pytest.raises(ValueError):
        BackgroundModel(0)
    model2 = BackgroundModel(2)
    model2.add(a)
    with pytest.raises(ValueError):
        model2.add(np.zeros((3, 3), np.float32))
    model.reset()
    assert not model.ready


def test_segmentation_params_are_validated():
    for bad in (dict(height_threshold_m=0.0), dict(min_area_px=0), dict(open_kernel_px=-1),
                dict(split_solidity=1.5), dict(core_ratio=1.0)):
        with pytest.raises(ValueError):
            SegmentationParams(**bad)


# ---------------------------------------------------------------- tracking


def test_ids_stable_and_lanes_right_over_50_frames_of_several_fillets():
    """9 fillets in 3 lanes (one touching pair) pass the view: one id per fillet for its whole passage."""
    across = {0: 0.16, 1: 0.0, 2: -0.16}
    leads = {0: [-0.05, -0.33, -0.62], 1: [-0.15, -0.15 - L + 0.005, -0.64], 2: [0.02, -0.30, -0.60]}
    fillets, lanes = [], []
    for lane, lane_leads in leads.items():
        for k, lead in enumerate(lane_leads):
            fillets.append(TopFillet(lead_m=lead, across_m=across[lane], curvature_per_m=3.0 + 5.0 * k))
            lanes.append(lane)
    scene = TopScene(fillets)
    background = scene.background_depth()
    tracker = CentroidTracker(lane_layout=LAYOUT3)
    ids_of_fillet: dict[int, set[int]] = {}
    fillets_of_id: dict[int, set[int]] = {}
    seen_frames: dict[int, int] = {}
    visible_frames: dict[int, int] = {}
    ended: list[int] = []
    for i in range(50):
        t = i / FPS
        blobs = segment_depth(scene.render(t)[1], background)
        update = tracker.update(blobs)
        ended += [track.track_id for track in update.ended]
        masks = fillet_masks(fillets, t)
        for k, m in enumerate(masks):
            if np.count_nonzero(m) >= 1500:
                visible_frames[k] = visible_frames.get(k, 0) + 1
        by_blob = {id(track.blob): track for track in update.active if track.unseen == 0}
        assert len(by_blob) == len(blobs), "every blob of this frame belongs to a track seen now"
        for blob in blobs:
            track = by_blob[id(blob)]
            k = owner(blob, masks)
            assert k >= 0, f"frame {i}: blob at {blob.centroid} is not mostly one fillet"
            ids_of_fillet.setdefault(k, set()).add(track.track_id)
            fillets_of_id.setdefault(track.track_id, set()).add(k)
            seen_frames[k] = seen_frames.get(k, 0) + 1
            assert track.lane == lanes[k], f"fillet {k} in lane {lanes[k]} tracked in lane {track.lane}"
    assert set(ids_of_fillet) == set(range(len(fillets))), "every fillet was segmented at some point"
    assert all(len(ids) == 1 for ids in ids_of_fillet.values()), ids_of_fillet
    assert all(len(ks) == 1 for ks in fillets_of_id.values()), fillets_of_id
    for k, frames in visible_frames.items():
        assert seen_frames.get(k, 0) >= 0.9 * frames, f"fillet {k} segmented in too few of its frames"
    # the three leaders fell past the edge long enough ago that their tracks ended, once each
    leaders = [next(iter(ids_of_fillet[k])) for k in (0, 3, 6)]
    assert sorted(set(ended) & set(leaders)) == sorted(leaders) and len(ended) == len(set(ended))


def test_track_ends_after_max_unseen_frames_exactly_once():
    tracker = CentroidTracker(max_unseen=5)
    for v in (100, 110, 120):
        update = tracker.update([square_blob(300, v)])
    (track,) = update.active
    for missed in range(1, 5):
        update = tracker.update([])
        assert [t.unseen for t in update.active] == [missed] and not update.ended
        assert update.active[0].blob.centroid == (300.0, 120.0)  # stale blob kept
    update = tracker.update([])
    assert update.active == [] and [t.track_id for t in update.ended] == [track.track_id]
    assert update.ended[0].unseen == 5
    assert tracker.update([]) == TrackUpdate(active=[], ended=[])


def test_new_blobs_open_new_tracks_and_ids_are_never_reused():
    tracker = CentroidTracker(max_distance_px=40.0, max_unseen=2)
    first = tracker.update([square_blob(100, 100)]).active[0].track_id
    update = tracker.update([square_blob(100, 108), square_blob(400, 100)])  # far beyond the gate: new track
    assert [t.track_id for t in update.active] == [first, first + 1]
    assert update.active[0].age == 2 and update.active[1].age == 1
    tracker.update([])
    update = tracker.update([])
    assert sorted(t.track_id for t in update.ended) == [first, first + 1]
    reopened = tracker.update([square_blob(100, 116)]).active
    assert [t.track_id for t in reopened] == [first + 2]
    tracker.reset()
    assert tracker.update([square_blob(100, 116)]).active[0].track_id == first + 3


def test_prediction_bridges_missed_frames():
    tracker = CentroidTracker(max_distance_px=20.0)
    for v in (100, 110, 120):
        (track,) = tracker.update([square_blob(200, v)]).active
    tracker.update([])
    tracker.update([])
    (again,) = tracker.update([square_blob(200, 150)]).active  # 30 px from the last sighting, 0 from prediction
    assert again.track_id == track.track_id and again.unseen == 0
    assert again.velocity == pytest.approx((0.0, 10.0))


def test_stale_track_ghost_does_not_steal_a_live_tracks_blob():
    """A fillet falling off the edge moves backwards in the image; its extrapolated ghost must not take over."""
    tracker = CentroidTracker(max_distance_px=40.0, max_unseen=15)
    for i in range(3):
        update = tracker.update([square_blob(300, 300 - 2 * i), square_blob(300, 200 + 6 * i)])
    ghost, live = (t.track_id for t in sorted(update.active, key=lambda t: -t.blob.centroid[1]))
    for i in range(3, 13):
        v = 200 + 6 * i + (3 if i == 12 else 0)  # at frame 12 the ghost's prediction (276) is nearer than live's
        update = tracker.update([square_blob(300, v)])
        matched = [t.track_id for t in update.active if t.unseen == 0]
        assert matched == [live], f"frame {i}"
    assert ghost in [t.track_id for t in update.active]


def test_lane_from_the_mean_column():
    tracker = CentroidTracker(lane_layout=LAYOUT3)
    blobs = [square_blob(LAYOUT3.lane_center_u(lane) + offset, 100) for lane, offset in ((0, 25), (1, -25), (2, 10))]
    update = tracker.update(blobs)
    assert {round(t.blob.centroid[0]): t.lane for t in update.active} == {
        round(b.centroid[0]): lane for b, lane in zip(blobs, (0, 1, 2))}
    assert LAYOUT3.lane_center_u(0) > LAYOUT3.lane_center_u(1) > LAYOUT3.lane_center_u(2)  # lane 0 on the right
    assert LAYOUT3.lane_of_u(10_000) == 0 and LAYOUT3.lane_of_u(-10_000) == 2  # clamped
    no_layout = CentroidTracker().update([square_blob(100, 100)]).active[0]
    assert no_layout.lane == -1
    assert lane_center_u(1, DEFAULT_TOP_K, TOP_CAMERA_HEIGHT_M, 3, 0.16) == pytest.approx(DEFAULT_TOP_K[2])


def test_tracker_validates_its_options():
    with pytest.raises(ValueError):
        CentroidTracker(max_distance_px=0.0)
    with pytest.raises(ValueError):
        CentroidTracker(max_unseen=0)


# ------------------------------------------------------------- frame checks


def image_msg(array: np.ndarray, encoding: str, stamp: float = 0.0, pad: int = 0, bigendian: bool = False,
              width: int | None = None, height: int | None = None):
    rows = np.ascontiguousarray(array)
    row_bytes = int(np.prod(rows.shape[1:])) * rows.itemsize
    raw = np.frombuffer(rows.tobytes(), np.uint8).reshape(rows.shape[0], row_bytes)
    if pad:
        raw = np.concatenate([raw, np.zeros((raw.shape[0], pad), np.uint8)], axis=1)
    sec = int(math.floor(stamp))
    return SimpleNamespace(
        encoding=encoding, height=rows.shape[0] if height is None else height,
        width=rows.shape[1] if width is None else width, step=raw.shape[1], data=raw.tobytes(),
        is_bigendian=int(bigendian),
        header=SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=int(round((stamp - sec) * 1e9)))))


def test_image_to_array_round_trips_and_handles_row_padding_and_endianness():
    depth = np.arange(12, dtype=np.float32).reshape(3, 4)
    assert np.array_equal(image_to_array(image_msg(depth, "32FC1"), "32FC1"), depth)
    assert np.array_equal(image_to_array(image_msg(depth, "32FC1", pad=8), "32FC1"), depth)
    swapped = depth.astype(">f4")
    assert np.array_equal(image_to_array(image_msg(swapped, "32FC1", bigendian=True), "32FC1"), depth)
    rgb = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
    assert np.array_equal(image_to_array(image_msg(rgb, "rgb8"), "rgb8"), rgb)


def test_image_to_array_rejects_wrong_encoding_and_size():
    depth = np.zeros((3, 4), np.float32)
    with pytest.raises(FrameError, match="encoding"):
        image_to_array(image_msg(depth, "16UC1"), "32FC1")
    with pytest.raises(FrameError):
        image_to_array(image_msg(depth, "32FC1", height=5), "32FC1")  # says 5 rows, holds 3
    with pytest.raises(FrameError):
        image_to_array(image_msg(depth, "32FC1", width=8), "32FC1")  # row step too short for 8 floats
    with pytest.raises(FrameError, match="empty"):
        image_to_array(image_msg(np.zeros((0, 4), np.float32), "32FC1"), "32FC1")
    with pytest.raises(FrameError, match="unsupported"):
        image_to_array(image_msg(depth, "yuv422"), "yuv422")
    msg = image_msg(depth, "32FC1")
    msg.data = msg.data[:-1]
    with pytest.raises(FrameError):
        image_to_array(msg, "32FC1")


class Logger:
    def __init__(self):
        self.lines: list[str] = []

    def warning(self, text: str) -> None:
        self.lines.append(text)


def test_frame_checker_flags_out_of_order_stamps_and_restarts():
    checker = FrameChecker(Logger())
    depth = np.zeros((3, 4), np.float32)
    checker.check(image_msg(depth, "32FC1", 10.0), depth.shape)
    checker.check(image_msg(depth, "32FC1", 10.1), depth.shape)
    with pytest.raises(FrameError, match="out-of-order"):
        checker.check(image_msg(depth, "32FC1", 10.05), depth.shape)
    with pytest.raises(FrameError, match="out-of-order"):
        checker.check(image_msg(depth, "32FC1", 10.1), depth.shape)  # a repeated stamp
    checker.check(image_msg(depth, "32FC1", 10.2), depth.shape)
    assert not checker.restarted
    checker.check(image_msg(depth, "32FC1", 2.0), depth.shape)  # far back in time: a restart (e.g. replay)
    assert checker.restarted
    checker.check(image_msg(depth, "32FC1", 2.1), depth.shape)
    assert not checker.restarted


def test_frame_checker_rejects_a_resize_until_it_persists():
    checker = FrameChecker(Logger())
    small, big = np.zeros((3, 4), np.float32), np.zeros((6, 8), np.float32)
    checker.check(image_msg(small, "32FC1", 0.0), small.shape)
    for i in range(1, RESIZE_CONFIRM_FRAMES):
        with pytest.raises(FrameError, match="size"):
            checker.check(image_msg(big, "32FC1", i * 0.1), big.shape)
    checker.check(image_msg(big, "32FC1", RESIZE_CONFIRM_FRAMES * 0.1), big.shape)
    assert checker.restarted


def test_frame_checker_counts_rejects_and_throttles_the_log():
    logger = Logger()
    checker = FrameChecker(logger, log_period_s=60.0)
    for _ in range(5):
        checker.reject("encoding 'bgr8' where rgb8 is expected; frame skipped")
    checker.reject("empty frame (0 pixels); frame skipped")
    assert checker.rejected == 6 and len(logger.lines) == 2


# ------------------------------------------------------------ grading rules


def test_grading_rules_classify_lower_phi_as_woody():
    rules = GradingRules(threshold=10.0)
    assert rules.classify(5.4).label == "woody" and rules.classify(19.1).label == "normal"
    assert rules.classify(10.0).label == "normal"  # strictly below the threshold is woody
    assert rules.classify(5.4).grade is None
    graded = GradingRules(threshold=10.0, moderate_threshold=12.0, severe_threshold=6.0)
    assert [graded.grade(p) for p in (3.0, 6.0, 11.0, 12.0, 20.0)] == [
        "severe", "moderate", "moderate", "normal", "normal"]
    assert graded.classify(11.0).label == "normal" and graded.classify(11.0).grade == "moderate"
    assert GradingRules(threshold=10.0, severe_threshold=4.0).grade(8.0) == "moderate"
    for bad_phi in (math.nan, math.inf):
        with pytest.raises(ValueError):
            rules.classify(bad_phi)


@pytest.mark.parametrize("kwargs", [
    dict(threshold=0.0), dict(threshold=-1.0), dict(threshold=math.nan), dict(threshold=math.inf),
    dict(threshold=True), dict(threshold="10"), dict(threshold=10.0, moderate_threshold=8.0),
    dict(threshold=10.0, severe_threshold=10.0), dict(threshold=10.0, severe_threshold=12.0),
    dict(threshold=10.0, moderate_threshold=6.0, severe_threshold=8.0), dict(threshold=10.0, severe_threshold=-1.0),
])
def test_grading_rules_are_validated(kwargs):
    with pytest.raises(ValueError):
        GradingRules(**kwargs)
