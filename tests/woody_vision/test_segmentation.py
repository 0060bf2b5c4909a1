"""woody_vision.segmentation on synthetic depth frames: touching fillets split, outlines kept, bad pixels handled.

Frames come from woody_vision.synthetic (a nadir pinhole camera over the belt end).
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from woody_common.line import TOP_CAMERA_HEIGHT_M
from woody_vision.camera_model import LaneLayout
from woody_vision.segmentation import (
    DEFAULT_HEIGHT_THRESHOLD_M,
    REAL_CAMERA_FILTERS,
    BackgroundModel,
    Blob,
    SegmentationParams,
    _split_by_tracks,
    height_map,
    segment_depth,
    segment_height_map,
    segment_mask,
)
from woody_vision.synthetic import (
    DEFAULT_TOP_K,
    TopFillet,
    TopScene,
)
from woody_vision.tracking import CentroidTracker

FPS = 30.0


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
        update = tracker.update(segment_depth(scene.render(i / FPS)[1], scene.background_depth()), i / FPS)
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


def test_height_map_is_background_minus_depth_with_every_missing_return_at_zero():
    """The compiled pass gives numpy's float32 values bit for bit; NaN, inf and depth <= 0 give 0."""
    rng = np.random.default_rng(3)
    background = np.full((37, 53), 0.75, np.float32)
    depth = background - rng.random(background.shape, dtype=np.float32) * 0.03
    depth[::7, ::5], depth[::11, ::3], depth[::13, ::2], depth[1, 1] = np.nan, 0.0, np.inf, -0.2
    background[2, ::4] = np.nan
    expected = np.subtract(background, depth, dtype=np.float32)
    with np.errstate(invalid="ignore"):
        expected[~np.isfinite(expected) | ~(depth > 0.0)] = 0.0
    height = height_map(depth, background)
    assert height.dtype == np.float32 and np.array_equal(height, expected)
    assert np.array_equal(height_map(depth.astype(np.float64)[:, ::-1], background[:, ::-1]), expected[:, ::-1])


def ellipses_mask(shape: tuple[int, int], offset: tuple[int, int]) -> np.ndarray:
    """Two touching fillet-sized ellipses, a lone one and a speck, shifted by ``offset`` (x, y)."""
    mask = np.zeros(shape, np.uint8)
    ox, oy = offset
    for centre, axes in (((60, 40), (45, 22)), ((140, 46), (45, 22)), ((110, 130), (40, 20)), ((30, 120), (3, 3))):
        cv2.ellipse(mask, (centre[0] + ox, centre[1] + oy), axes, 10.0, 0, 360, 255, -1)
    return mask


def test_blobs_are_found_in_the_box_of_fillet_pixels_as_in_the_whole_frame():
    """segment_mask opens and labels only the bounding box of the fillet pixels; the blobs must be those of the
    whole frame, so moving the fillets across a larger frame moves every blob and changes nothing else."""
    params = SegmentationParams()
    height = np.full((376, 672), 0.02, np.float32)
    near = segment_mask(ellipses_mask((376, 672), (4, 3)), height, params)
    far = segment_mask(ellipses_mask((376, 672), (300, 200)), height, params)
    assert len(near) == len(far) == 3  # the touching pair split, the speck dropped
    for a, b in zip(near, far):
        assert np.array_equal(a.contour + [296, 197], b.contour) and a.area_px == b.area_px
        assert a.bbox[2:] == b.bbox[2:] and (a.bbox[0] + 296, a.bbox[1] + 197) == b.bbox[:2]
        assert np.allclose(np.add(a.centroid, (296, 197)), b.centroid)


def test_a_fillet_cut_by_the_frame_edge_keeps_its_edge_pixels():
    """The image border still counts as fillet for the opening (OpenCV's default), as on the whole frame."""
    mask = np.zeros((376, 672), np.uint8)
    cv2.ellipse(mask, (200, 5), (45, 22), 0.0, 0, 360, 255, -1)
    (blob,) = segment_mask(mask, np.full(mask.shape, 0.02, np.float32), SegmentationParams())
    opened = cv2.morphologyEx(mask, cv2.MORPH_OPEN, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5)))
    assert blob.bbox[1] == 0 and blob.area_px == cv2.countNonZero(opened)  # the whole frame, opened


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
                dict(split_solidity=1.5), dict(core_ratio=1.0), dict(height_core_floor=0.8),
                dict(height_core_floor=0.0), dict(color_threshold=-1.0),
                dict(color_search_px=-1), dict(split_length_px=-1.0), dict(split_area_px=-1.0)):
        with pytest.raises(ValueError):
            SegmentationParams(**bad)


BELT, PINK = (58, 64, 82), (226, 150, 138)


def outlines(blobs: list[Blob]) -> list[list]:
    return [blob.contour.tolist() for blob in blobs]


def dome_scene(rng: np.random.Generator, noise_m: float = 0.002) -> tuple[np.ndarray, ...]:
    """A fillet-like dome (20 mm high, its rim tapering to the belt) under correlated depth noise, and its colour.

    Returns (depth, background depth, colour, background colour, true mask)."""
    rows, cols = np.mgrid[0:200, 0:300]
    r2 = ((cols - 150) / 90.0) ** 2 + ((rows - 100) / 45.0) ** 2
    truth = r2 < 1.0
    background = np.full((200, 300), 0.75, np.float32)
    noise = cv2.GaussianBlur(rng.standard_normal(background.shape).astype(np.float32), (0, 0), 1.5)
    depth = background - np.where(truth, 0.02 * (1.0 - r2), 0.0).astype(np.float32)
    depth += noise / noise.std() * np.float32(noise_m)
    color_bg = np.empty((200, 300, 3), np.float32)
    color_bg[:] = BELT
    color = np.where(truth[..., None], np.float32(PINK), color_bg) + rng.normal(0.0, 3.0, color_bg.shape)
    return depth, background, np.clip(color, 0, 255).astype(np.uint8), color_bg, truth


def test_colour_draws_the_outline_that_depth_noise_frays():
    """A thin rim under 2 mm of depth noise: the 5 mm cut loses the rim and frays; the colour outline is the fillet."""
    depth, background, color, color_bg, truth = dome_scene(np.random.default_rng(3))
    true_contour, _ = cv2.findContours(truth.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    params = SegmentationParams(**dict(REAL_CAMERA_FILTERS, color_search_px=16))  # wider than the lost rim
    (from_depth,) = segment_depth(depth, background, params)
    (from_color,) = segment_depth(depth, background, params, color, color_bg)
    assert outlines(segment_depth(depth, background, params, None, color_bg)) == outlines([from_depth])
    assert from_depth.area_px < 0.85 * truth.sum()  # the rim under the 5 mm cut is lost
    assert from_color.area_px == pytest.approx(truth.sum(), rel=0.03)

    def distance(blob):
        return cv2.matchShapes(true_contour[0], blob.contour, cv2.CONTOURS_MATCH_I1, 0.0)

    assert distance(from_color) < 0.2 * distance(from_depth)
    off = SegmentationParams(**dict(REAL_CAMERA_FILTERS, color_threshold=0.0))
    without = segment_depth(depth, background, off)
    assert outlines(segment_depth(depth, background, off, color, color_bg)) == outlines(without)


def test_colour_counts_only_near_the_depth_mask():
    """A pink stain on the flat belt is no fillet, and one running out of a fillet ends color_search_px past it."""
    depth, background, color, color_bg, truth = dome_scene(np.random.default_rng(4), noise_m=0.0)
    params = SegmentationParams(**REAL_CAMERA_FILTERS)
    (alone,) = segment_depth(depth, background, params, color, color_bg)
    stained = color.copy()
    stained[150:195, 10:60] = PINK  # far from the fillet
    stained[95:105, 200:300] = PINK  # from inside the fillet out to the frame border
    (blob,) = segment_depth(depth, background, params, stained, color_bg)
    (depth_only,) = segment_depth(depth, background, SegmentationParams(**dict(REAL_CAMERA_FILTERS, color_threshold=0)))
    right_end = depth_only.bbox[0] + depth_only.bbox[2] - 1
    assert blob.bbox[0] + blob.bbox[2] - 1 == right_end + params.color_search_px
    assert outlines([blob]) == outlines([alone])
    with pytest.raises(ValueError, match="registered"):
        segment_depth(depth, background, params, color[:, :-1], color_bg)


def test_background_model_learns_the_colour_of_the_empty_belt():
    model = BackgroundModel(frames_needed=3)
    depth = np.full((4, 5), 0.75, np.float32)
    for level in (10, 200, 30):
        model.add(depth, np.full((4, 5, 3), level, np.uint8))
    assert model.color.shape == (4, 5, 3) and np.all(model.color == 30.0)  # the median: a passer-by is ignored
    assert BackgroundModel(1).color is None
    without = BackgroundModel(1)
    without.add(depth)
    assert without.ready and without.color is None
    with pytest.raises(ValueError, match="colour shape"):
        BackgroundModel(1).add(depth, np.zeros((4, 4, 3), np.uint8))
    model.reset()
    assert model.color is None and not model.ready


def render_flat(placed: list[tuple[int, object, float]], pitch: float = 0.11) -> tuple[np.ndarray, np.ndarray, float]:
    """Depth and background of simulated fillets lying flat: (lane, mesh, lateral offset) each; and px per metre."""
    from woody_sim.line_geometry import LineGeometry
    from woody_sim.line_world import LineWorld, calibrated_config
    from woody_sim.rendering import LineRenderer

    geometry = LineGeometry(lanes=2, lane_pitch=pitch, spawn_x=-0.3)
    renderer = LineRenderer(geometry, render_side=False)
    background = renderer.render_top({})[1]
    with LineWorld(geometry, calibrated_config()) as world:
        for lane, mesh, offset in placed:
            fid = world.spawn(mesh, 0.0, lane, 20.0, 0.508, lateral_offset=offset)
            renderer.add_fillet(fid, lane, world.model(fid).visuals)
        world.step()
        depth = renderer.render_top(world.segment_poses())[1]
    return depth, background, float(geometry.top_camera().k[0, 0]) / geometry.top_height


def test_fillets_lying_side_by_side_along_their_length_are_split_by_height():
    """Two large fillets pushed together across a 0.11 m lane pitch: one solid blob without notches, which only
    the height relief (two thick middles) tells apart; a single turned large fillet, as wide, stays whole."""
    from woody_sim.meshes import generate_fillet, scaled, yawed

    big = [scaled(generate_fillet(seed), 1.15) for seed in (0, 5)]
    depth, background, px_per_m = render_flat([(0, big[0], -0.02), (1, big[1], 0.02)])
    wide = SegmentationParams(split_width_px=0.13 * px_per_m)
    assert len(segment_depth(depth, background)) == 1, "precondition: one blob without the width check"
    halves = segment_depth(depth, background, wide)
    assert len(halves) == 2 and min(b.area_px for b in halves) > 0.35 * sum(b.area_px for b in halves)
    depth, background, _ = render_flat([(0, yawed(big[0], 35.0), 0.0)])
    (whole,) = segment_depth(depth, background, wide)
    assert whole.bbox[2] > wide.split_width_px


def test_fillets_side_by_side_reaching_past_the_roller_edge_are_split_by_their_middles_on_the_belt():
    """Two domed fillets touching side by side whose fronts hang past the edge, where the background is the floor
    and the height reads over half a metre: the split is seeded on the middles still lying on the belt."""
    rows, cols = np.mgrid[0:200, 0:240]
    height = np.zeros((200, 240), np.float32)
    for centre in (90.0, 150.0):  # nearly rectangular outlines: no notch where they touch
        across, along = (cols - centre) / 31.0, (rows - 90.0) / 70.0
        inside = across ** 6 + along ** 6 < 1.0
        height = np.maximum(height, np.where(inside, 0.004 + 0.022 * np.sqrt(np.clip(1.0 - across ** 2, 0, 1)), 0.0))
    height[150:175, 60:120] = np.where(height[150:175, 60:120] > 0, 0.6, 0.0)  # a front over the floor
    params = SegmentationParams(split_width_px=80.0)
    assert len(segment_height_map(height, SegmentationParams())) == 1, "precondition: one solid blob"
    blobs = segment_height_map(height, params)
    assert len(blobs) == 2
    assert sorted(round(b.centroid[0] / 10) for b in blobs) == [9, 15]


def test_a_thin_fillet_touching_a_thick_one_side_by_side_is_split_below_the_first_cut():
    """A 15 mm fillet beside a 27 mm one: no pixel of the thin one rises above 0.75 x the thick one's height, so
    only a lower cut of the relief (``height_core_floor``) finds its middle, above the saddle where they touch."""
    rows, cols = np.mgrid[0:200, 0:240]
    height = np.zeros((200, 240), np.float32)
    for centre, top in ((90.0, 0.015), (150.0, 0.027)):
        across, along = (cols - centre) / 31.0, (rows - 90.0) / 70.0
        inside = across ** 6 + along ** 6 < 1.0
        height = np.maximum(height, np.where(inside, 0.004 + top * np.sqrt(np.clip(1.0 - across ** 2, 0, 1)), 0.0))
    one_cut = SegmentationParams(split_width_px=80.0)
    assert float(height[:, :120].max()) < one_cut.height_core_ratio * float(height.max()), "precondition: thin"
    assert len(segment_height_map(height, one_cut)) == 1, "the default cut finds the thick one's middle only"
    blobs = segment_height_map(height, SegmentationParams(split_width_px=80.0, height_core_floor=0.5))
    assert sorted(round(b.centroid[0] / 10) for b in blobs) == [9, 15]
    area = float(np.count_nonzero(height > DEFAULT_HEIGHT_THRESHOLD_M))
    larger = SegmentationParams(split_width_px=80.0, split_area_px=0.9 * area)
    assert sorted(round(b.centroid[0] / 10) for b in segment_height_map(height, larger)) == [9, 15], \
        "covering more belt than one fillet can, the pair is split at the default floor too"
    assert len(segment_height_map(height, SegmentationParams(split_width_px=80.0, split_area_px=1.1 * area))) == 1


def test_two_fillets_touching_end_to_end_without_a_neck_are_split_by_height_when_too_long_for_one():
    """A 17 mm fillet whose blunt end touches a 28 mm one's across its whole width: one solid blob with no neck, no
    notch and no pixel of the thin one above 0.75 x the thick one's height. Longer along the flow than one fillet
    can be, it is two, and the relief cut lower finds both middles; the same blob under that length stays whole."""
    rows, cols = np.mgrid[0:240, 0:120]
    height = np.zeros((240, 120), np.float32)
    for centre, top in ((60.0, 0.017), (170.0, 0.028)):  # nearly rectangular: full width where they touch
        across, along = (cols - 60.0) / 30.0, (rows - centre) / 56.0
        inside = across ** 6 + along ** 6 < 1.0
        dome = 0.003 + top * np.sqrt(np.clip(1.0 - along ** 2, 0, 1))
        height = np.maximum(height, np.where(inside, dome, 0.0))
    assert len(segment_height_map(height, SegmentationParams())) == 1, "precondition: one solid blob"
    long = SegmentationParams(split_length_px=180.0)
    blobs = segment_height_map(height, long)
    assert sorted(round(b.centroid[1] / 10) for b in blobs) == [6, 17]
    assert len(segment_height_map(height, SegmentationParams(split_length_px=240.0))) == 1


def test_a_wide_fillet_reading_thicker_over_the_roller_crown_is_not_split_along_the_flow():
    """A turned fillet wider than ``split_width_px`` crossing the edge: over the roller's crown the background falls
    away, so a band of it reads as high as its middle, a second thick core ahead of the first. One fillet's thick
    parts one behind the other are not fillets side by side: it stays one blob."""
    rows, cols = np.mgrid[0:200, 0:240]
    across, along = (cols - 120.0) / 45.0, (rows - 90.0) / 70.0
    inside = across ** 2 + along ** 2 < 1.0
    dome = 0.004 + 0.018 * np.sqrt(np.clip(1.0 - across ** 2 - along ** 2, 0, 1))
    height = np.where(inside, dome, 0.0).astype(np.float32)
    crown = inside & (rows >= 148) & (rows < 154)
    height[crown] = 0.021  # the band over the crown, higher than 0.75 x the middle's 0.022 m
    height[inside & (rows >= 154)] = 0.6  # the front over the floor
    params = SegmentationParams(split_width_px=80.0)
    assert cv2.boundingRect((height > 0).astype(np.uint8))[2] > params.split_width_px, "precondition: wide"
    (blob,) = segment_height_map(height, params)
    assert blob.area_px > 0.95 * np.count_nonzero(inside)


NO_SPLIT_BY_TRACKS = SegmentationParams(split_by_tracks=False)


def rectangle(u0: int, v0: int, width: int, rows: int) -> np.ndarray:
    """The outline (image coordinates) of a width x rows rectangle from column u0, row v0."""
    return np.array([[u0, v0], [u0 + width - 1, v0], [u0 + width - 1, v0 + rows - 1], [u0, v0 + rows - 1]], np.int32)


def test_a_blob_holding_two_tracked_fillets_is_split_where_their_priors_lie():
    """Two fillets side by side with nothing to part them (a solid block: no neck, one height) are one blob; the
    tracker's priors of both split it into the two, each on its own side."""
    mask = np.zeros((200, 300), np.uint8)
    left, right = rectangle(100, 50, 40, 100), rectangle(140, 50, 40, 100)
    cv2.fillPoly(mask, [left, right], 255)
    height = np.full(mask.shape, 0.02, np.float32)
    assert len(segment_mask(mask, height, SegmentationParams())) == 1
    moved = [left + [0, 4], right + [2, -3]]  # predictions a few pixels off
    assert len(segment_mask(mask, height, NO_SPLIT_BY_TRACKS, moved)) == 1  # the split can be turned off
    split = segment_mask(mask, height, SegmentationParams(), moved)
    assert len(split) == 2
    by_column = sorted(split, key=lambda b: b.centroid[0])
    assert abs(by_column[0].centroid[0] - 119.5) < 3 and abs(by_column[1].centroid[0] - 159.5) < 3
    assert abs(by_column[0].area_px - 4000) < 300 and abs(by_column[1].area_px - 4000) < 300


def test_a_slivers_prior_or_two_priors_of_one_fillet_never_split_it():
    mask = np.zeros((200, 300), np.uint8)
    whole = rectangle(100, 50, 60, 100)
    cv2.fillPoly(mask, [whole], 255)
    height = np.full(mask.shape, 0.02, np.float32)
    sliver = rectangle(140, 60, 15, 25)
    assert len(segment_mask(mask, height, SegmentationParams(), [whole, sliver])) == 1
    halves = [rectangle(100, 50, 30, 100), rectangle(130, 50, 30, 100)]  # no growth past the larger: one fillet
    assert len(segment_mask(mask, height, SegmentationParams(), [whole, *halves])) == 1
    assert len(segment_mask(mask, height, SegmentationParams(), [rectangle(10, 10, 20, 20)] * 2)) == 1


def test_a_geometric_split_through_a_tracked_fillet_is_overruled_by_the_priors():
    """Three fillets side by side entering as one blob, parted through the middle one by its notches: each
    tracked fillet's prior gets its own piece, not half of the middle one; a prior longer than one fillet (a track
    that followed two joined end to end) does not overrule the cut."""
    block = np.zeros((200, 300), np.uint8)
    fillets = [rectangle(100, 50, 40, 100), rectangle(140, 50, 40, 100), rectangle(180, 50, 40, 100)]
    cv2.fillPoly(block, fillets, 255)
    component, origin = block[49:151, 99:221].copy(), (99, 49)
    halves = [np.zeros_like(component) for _ in range(2)]
    halves[0][:, :61], halves[1][:, 61:] = component[:, :61], component[:, 61:]  # cut at column 160
    params = SegmentationParams(split_width_px=50.0, split_length_px=150.0, split_area_px=6000.0)
    pieces = _split_by_tracks([(h, None) for h in halves], fillets, origin, params)
    assert len(pieces) == 3
    areas = sorted(cv2.countNonZero(mask) for mask, _ in pieces)
    assert all(abs(area - 4000) < 400 for area in areas), areas
    long_track = [rectangle(140, 50, 40, 160)]  # longer than split_length_px: two fillets joined
    kept = _split_by_tracks([(h, None) for h in halves], [fillets[0], *long_track], origin, params)
    assert sorted(cv2.countNonZero(m) for m, _ in kept) == sorted(cv2.countNonZero(h) for h in halves)


def test_only_the_parts_that_cut_a_prior_are_split_again_from_the_priors():
    """Three fillets side by side, the middle one parted by the geometry into two parts: those two are joined and
    split from the priors, while the right fillet keeps its clean part although its track's prior holds a piece of
    the middle one (the track took it as they entered), so the piece does not stay with it."""
    block = np.zeros((200, 300), np.uint8)
    fillets = [rectangle(100, 50, 40, 100), rectangle(140, 50, 40, 100), rectangle(180, 50, 40, 100)]
    cv2.fillPoly(block, fillets, 255)
    component, origin = block[49:151, 99:221].copy(), (99, 49)
    parts = [np.zeros_like(component) for _ in range(3)]
    for part, (first, last) in zip(parts, ((0, 61), (61, 81), (81, None))):  # cut at columns 160 and 180
        part[:, first:last] = component[:, first:last]
    with_piece = np.array([[180, 50], [219, 50], [219, 149], [160, 149], [160, 100], [180, 100]], np.int32)
    params = SegmentationParams(split_width_px=50.0, split_length_px=150.0, split_area_px=6000.0)
    pieces = _split_by_tracks([(p, None) for p in parts], [*fillets[:2], with_piece], origin, params)
    assert len(pieces) == 3
    right = max(pieces, key=lambda piece: cv2.boundingRect(piece[0])[0])[0]
    assert cv2.countNonZero(cv2.bitwise_xor(right, parts[2])) == 0
    assert all(abs(cv2.countNonZero(mask) - 4000) < 400 for mask, _ in pieces)


def test_a_fillet_reaching_the_one_hanging_ahead_of_it_is_split_from_it():
    """End to end, with the priors a few rows off where each lies (the one ahead falls slower than the belt)."""
    tip_to_tail = np.zeros((300, 300), np.uint8)
    cv2.fillPoly(tip_to_tail, [rectangle(100, 20, 50, 100), rectangle(100, 120, 50, 100)], 255)
    ahead, behind = rectangle(100, 125, 50, 100), rectangle(100, 15, 50, 100)
    blobs = segment_mask(tip_to_tail, np.full(tip_to_tail.shape, 0.02, np.float32), SegmentationParams(),
                         [ahead, behind])
    assert len(blobs) == 2
    first, second = sorted(blobs, key=lambda b: b.centroid[1])
    assert abs(int(first.contour[:, 1].max()) - 120) <= 6  # parted where the two meet
    assert abs(second.area_px - first.area_px) <= 0.1 * first.area_px
