"""Side-view bending metrics on synthetic frames with known geometry: MDM, NMDM, thinning, BE, passages."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from woody_vision.side_view import (
    REASON_SIDE_GAP,
    SideMeasurement,
    SidePassageTracker,
    bending_energy,
    difference_mask,
    mdm,
    nmdm,
    silhouette,
    zhang_suen_thinning,
)
from woody_vision.synthetic import FILLET_RGB, SideScene, SideStrip

SCENE = SideScene()
AXLE = SCENE.axle_uv
R = SCENE.roller_radius_px
DT = 1.0 / 200.0


def with_disc(centre: tuple[float, float], radius: float) -> np.ndarray:
    """The side background with a fillet-coloured disc drawn at a sub-pixel centre."""
    rgb = SCENE.background()
    shift = 4
    cv2.circle(rgb, (round(centre[0] * 16), round(centre[1] * 16)), round(radius * 16), FILLET_RGB, -1, cv2.LINE_8,
               shift)
    return rgb


def flush(tracker: SidePassageTracker, stamp: float, frames: int = 4) -> list:
    """Empty frames after the last fillet left, so its passage ends."""
    out = []
    for j in range(frames):
        out += tracker.update(SCENE.background(), stamp + j * DT)
    return out


def test_mdm_and_nmdm_arithmetic():
    assert mdm((3.0, 4.0), (0.0, 0.0)) == pytest.approx(5.0)
    assert mdm(AXLE, AXLE) == 0.0
    assert nmdm(60.0, 48.0, 12.0) == pytest.approx(1.0)
    assert nmdm(40.0, 48.0, 12.0) == pytest.approx(40.0 / 60.0)


def test_disc_silhouette_centroid_and_mdm():
    centre = (530.3, 251.7)
    mask = silhouette(with_disc(centre, 20.0), SCENE.background())
    m = cv2.moments(mask, binaryImage=True)
    assert (m["m10"] / m["m00"], m["m01"] / m["m00"]) == pytest.approx(centre, abs=0.3)
    assert m["m00"] == pytest.approx(math.pi * 20.5**2, rel=0.02)  # drawn pixels include the rim
    assert mdm((m["m10"] / m["m00"], m["m01"] / m["m00"]), AXLE) == pytest.approx(math.dist(centre, AXLE), abs=0.3)


def disc_passage(r: float = 20.0) -> list[tuple[float, float]]:
    """Centres of a disc rolling along the belt to the roller, then circling the axle."""
    closest = 0.8 * (R + r)
    frames = [(u, AXLE[1] - R - r) for u in np.arange(150.0, 400.0, 25.0)]
    return frames + [(AXLE[0] + closest * math.sin(a), AXLE[1] - closest * math.cos(a))
                     for a in np.radians(np.arange(-70.0, 71.0, 10.0))]


def test_passage_of_a_disc_gives_known_min_mdm_h_and_nmdm():
    """A disc of radius r rolls along the belt (h = r), then circles the axle at distance D: NMDM = D / (R + r)."""
    r = 20.0
    closest = 0.8 * (R + r)
    tracker = SidePassageTracker(AXLE, R, background=SCENE.background())
    frames = disc_passage(r)
    out = []
    for i, centre in enumerate(frames):
        out += tracker.update(with_disc(centre, r), i * DT)
        assert out == [], "no measurement while the passage is still in view"
    out += flush(tracker, len(frames) * DT)
    (m,) = out
    assert m.h_px == pytest.approx(r, abs=1.0)
    assert m.mdm_min_px == pytest.approx(closest, abs=0.5)
    assert m.nmdm == pytest.approx(closest / (R + r), abs=0.015)
    assert m.frames == len(frames) and m.first_stamp == 0.0 and m.last_stamp == pytest.approx((len(frames) - 1) * DT)
    assert m.stamp_of_min == pytest.approx((len(frames) - 1 - 7) * DT)  # the frame at the top of the roller


def test_a_fillet_first_seen_past_the_h_trigger_gives_no_measurement():
    """h is taken when the leading edge crosses axle + R; a fillet that enters already past it has no h."""
    tracker = SidePassageTracker(AXLE, R, background=SCENE.background())
    for i, a in enumerate(np.radians([50.0, 70.0, 90.0])):
        tracker.update(with_disc((AXLE[0] + 70 * math.sin(a), AXLE[1] - 70 * math.cos(a)), 20.0), i * DT)
    assert flush(tracker, 1.0) == []


def strip_passage(tracker: SidePassageTracker, drape: bool, leads, t0: float = 0.0, behind: float | None = None):
    out = []
    for i, lead in enumerate(leads):
        strips = [SideStrip(lead_px=float(lead), drape=drape)]
        if behind is not None:
            strips.append(SideStrip(lead_px=float(lead) - behind, drape=drape))
        out += tracker.update(SCENE.render(strips), t0 + i * DT)
    return out


def test_draping_strip_has_lower_nmdm_than_a_rigid_one():
    leads = np.arange(-300.0, 161.0, 20.0)
    results = {}
    for drape in (True, False):
        tracker = SidePassageTracker(AXLE, R, background=SCENE.background())
        out = strip_passage(tracker, drape, leads)
        assert out == []
        (results[drape],) = flush(tracker, len(leads) * DT)
    rigid, draping = results[False], results[True]
    thickness = SideStrip(0.0).thickness_px
    assert rigid.h_px == pytest.approx(thickness / 2, abs=1.0)
    assert thickness / 2 - 1.0 <= draping.h_px <= thickness, "h at the trigger: the drooping tip lowers the centroid"
    assert rigid.nmdm == pytest.approx(1.0, abs=0.03)  # a cantilever's centroid passes the roller top at R + t/2
    assert draping.nmdm < rigid.nmdm - 0.2
    assert draping.mdm_min_px < R + thickness / 2 - 10.0
    assert rigid.be < 1e-6


def test_one_measurement_per_passage_with_two_fillets_in_view():
    tracker = SidePassageTracker(AXLE, R, background=SCENE.background())
    leads = np.arange(-200.0, 161.0, 20.0)
    behind = 420.0
    out = strip_passage(tracker, True, leads, behind=behind)  # the second strip follows 420 px behind
    assert out == []
    # the first strip falls away; the second goes on over the roller
    rest = leads[-1] - behind + np.arange(20.0, 20.0 * 40, 20.0)
    rest = rest[rest <= 160.0]
    t1 = len(leads) * DT
    out = strip_passage(tracker, True, rest, t0=t1)
    assert len(out) == 1, "the first passage ends once, while the second is still in view"
    first = out[0]
    assert first.first_stamp == 0.0 and first.last_stamp == pytest.approx((len(leads) - 1) * DT)
    out = flush(tracker, t1 + len(rest) * DT)
    assert len(out) == 1
    second = out[0]
    assert second.first_stamp > 0.0 and second.last_stamp == pytest.approx(t1 + (len(rest) - 1) * DT)
    assert second.nmdm == pytest.approx(first.nmdm, abs=0.05)
    assert flush(tracker, 10.0) == []


def test_tracker_learns_the_background_from_its_first_frame_and_relearns_on_a_new_size():
    tracker = SidePassageTracker(AXLE, R)
    assert tracker.update(SCENE.background(), 0.0) == []
    out = []
    for i, u in enumerate(np.arange(150.0, 400.0, 50.0)):
        out += tracker.update(with_disc((u, AXLE[1] - R - 20.0), 20.0), (i + 1) * DT)
    assert tracker.update(np.zeros((10, 10, 3), np.uint8), 1.0) == []  # a new size: relearn, drop passages
    assert tracker.background.shape == (10, 10, 3)
    tracker.reset()
    assert tracker.background is None
    with pytest.raises(ValueError):
        SidePassageTracker(AXLE, 0.0)
    with pytest.raises(ValueError):
        SidePassageTracker(AXLE, R, end_frames=0)


# --------------------------------------------------------------- skeleton and BE


def strip_mask(curvature: float, thickness: int = 14, shape=(220, 320)) -> np.ndarray:
    """A thick parabola y = 60 + curvature·(x − 160)² from x = 30 to 290 (curvature 0: a straight bar)."""
    mask = np.zeros(shape, np.uint8)
    xs = np.arange(30, 291)
    ys = 60.0 + curvature * (xs - 160.0) ** 2
    cv2.polylines(mask, [np.round(np.stack([xs, ys], 1)).astype(np.int32).reshape(-1, 1, 2)], False, 255, thickness)
    return mask


def test_thinning_gives_a_one_pixel_connected_skeleton_inside_the_mask():
    for mask in (strip_mask(0.0), strip_mask(0.005)):
        skeleton = zhang_suen_thinning(mask)
        assert skeleton.any() and not (skeleton & (mask == 0)).any()
        blocks = skeleton[:-1, :-1] & skeleton[1:, :-1] & skeleton[:-1, 1:] & skeleton[1:, 1:]
        assert not blocks.any(), "no 2x2 block survives thinning"
        count, _ = cv2.connectedComponents(skeleton.astype(np.uint8), connectivity=8)
        assert count == 2
    bar = zhang_suen_thinning(strip_mask(0.0))
    ys, xs = np.nonzero(bar)
    assert np.ptp(xs) > 230 and np.ptp(ys) <= 2
    assert zhang_suen_thinning(np.zeros((5, 5), np.uint8)).sum() == 0


def textbook_thinning(mask: np.ndarray) -> np.ndarray:
    """Zhang & Suen (1984) as printed: every pixel tested in every sub-iteration, removals applied together."""
    img = np.pad((mask > 0).astype(np.uint8), 1)
    while True:
        changed = False
        for step in (0, 1):
            p = [img[:-2, 1:-1], img[:-2, 2:], img[1:-1, 2:], img[2:, 2:],  # P2 (north) .. P9, clockwise
                 img[2:, 1:-1], img[2:, :-2], img[1:-1, :-2], img[:-2, :-2]]
            count = sum(q.astype(int) for q in p)
            transitions = sum(((p[i] == 0) & (p[(i + 1) % 8] == 1)).astype(int) for i in range(8))
            if step == 0:
                rule = (p[0] * p[2] * p[4] == 0) & (p[2] * p[4] * p[6] == 0)
            else:
                rule = (p[0] * p[2] * p[6] == 0) & (p[0] * p[4] * p[6] == 0)
            remove = (img[1:-1, 1:-1] == 1) & (count >= 2) & (count <= 6) & (transitions == 1) & rule
            if remove.any():
                img[1:-1, 1:-1][remove] = 0
                changed = True
        if not changed:
            return img[1:-1, 1:-1].astype(bool)


def test_thinning_equals_the_textbook_algorithm_pixel_for_pixel():
    rng = np.random.default_rng(4)
    for i in range(60):
        h, w = (int(v) for v in rng.integers(5, 120, 2))
        mask = np.zeros((h, w), np.uint8)
        for _ in range(3):
            centre = (int(rng.integers(0, w)), int(rng.integers(0, h)))
            axes = (int(rng.integers(1, 60)), int(rng.integers(1, 25)))
            cv2.ellipse(mask, centre, axes, float(rng.uniform(0, 180)), 0, 360, 1, -1)
        if i % 4 == 0:
            mask = (rng.random((h, w)) < 0.5).astype(np.uint8)  # speckle: many small components and holes
        assert np.array_equal(zhang_suen_thinning(mask), textbook_thinning(mask)), f"mask {i}"


def test_silhouette_outline_is_smooth_so_a_stair_stepped_bend_keeps_its_bending_energy():
    """The seed's blur and closing: a bend drawn in 4-pixel stair steps (a coarse render, a folded chain's
    slices) has the bending energy of the same bend drawn smoothly, not one inflated by skeleton spurs."""
    xs = np.arange(250, 700)
    centre_y = 330.0 + 0.0015 * (xs - 475.0) ** 2
    smooth, stepped = SCENE.background().copy(), SCENE.background().copy()
    for x, y in zip(xs, centre_y):
        smooth[int(y) - 12:int(y) + 12, x] = (230, 150, 130)
        step_y = 4 * round(y / 4)
        stepped[step_y - 12:step_y + 12, x - x % 4:x - x % 4 + 4] = (230, 150, 130)
    bends = [bending_energy(silhouette(image, SCENE.background())) for image in (smooth, stepped)]
    assert bends[1] == pytest.approx(bends[0], rel=0.15)


def test_bending_energy_zero_for_straight_and_growing_with_curvature():
    assert bending_energy(strip_mask(0.0)) < 1e-6
    line = np.zeros((50, 200), np.uint8)
    line[25, 10:190] = 255
    assert bending_energy(line) < 1e-6
    energies = [bending_energy(strip_mask(c)) for c in (0.002, 0.005, 0.01)]
    assert energies[0] > 1.0
    assert all(b > 1.5 * a for a, b in zip(energies, energies[1:])), energies
    assert math.isnan(bending_energy(np.zeros((20, 20), np.uint8)))
    column = np.zeros((60, 20), np.uint8)
    column[5:55, 10] = 255  # vertical: straight in its principal-axis frame
    assert bending_energy(column) < 1e-6
    bent = np.pad(strip_mask(0.005), 150)
    h, w = bent.shape
    turned = cv2.warpAffine(bent, cv2.getRotationMatrix2D((w / 2.0, h / 2.0), 35.0, 1.0), (w, h),
                            flags=cv2.INTER_NEAREST)
    assert bending_energy(turned) == pytest.approx(bending_energy(bent), rel=0.25), \
        "BE follows the tilt only through P², whose pixel-chain perimeter grows up to ~10 % on a diagonal"


def test_the_difference_mask_sums_absolute_channel_differences_beyond_255_and_refuses_other_shapes():
    rng = np.random.default_rng(4)
    background = rng.integers(0, 256, (7, 9, 3), dtype=np.uint8)
    image = rng.integers(0, 256, (7, 9, 3), dtype=np.uint8)
    total = np.abs(image.astype(int) - background.astype(int)).sum(axis=2)
    for threshold in (0, 40, 300, 700):
        expected = np.where(total > threshold, 255, 0)
        np.testing.assert_array_equal(difference_mask(image, background, threshold), expected)
    strided = np.zeros((7, 18, 3), np.uint8)[:, ::2]  # a view with a row step, as a padded Image gives
    assert not difference_mask(strided, np.zeros((7, 9, 3), np.uint8), 0).any()
    with pytest.raises(ValueError, match="two \\(H, W, 3\\) images"):
        difference_mask(image[..., 0], background[..., 0], 40)


def measure(lost: set[int], idle_before: int = 0) -> SideMeasurement:
    """The disc's passage with the ``lost`` frames missing, after ``idle_before`` empty frames at the idle rate."""
    tracker = SidePassageTracker(AXLE, R, background=SCENE.background())
    t0 = idle_before * 0.5
    for j in range(idle_before):
        assert tracker.update(SCENE.background(), j * 0.5) == []
    out = [m for i, centre in enumerate(disc_passage()) if i not in lost
           for m in tracker.update(with_disc(centre, 20.0), t0 + i * DT)]
    (m,) = out + flush(tracker, t0 + len(disc_passage()) * DT)
    return m


def test_a_passage_with_lost_frames_has_no_side_metrics_but_the_reason():
    whole = measure(set())
    assert whole.complete and whole.reason == "" and math.isfinite(whole.nmdm)
    middle = len(disc_passage()) - 8  # the disc at the top of the roller: the minimum MDM is lost with it
    gap = measure({middle - 1, middle, middle + 1})
    assert not gap.complete and gap.reason == REASON_SIDE_GAP.format(4 * DT, DT)
    assert math.isnan(gap.nmdm) and math.isnan(gap.mdm_min_px) and math.isnan(gap.be)
    assert (gap.first_stamp, gap.last_stamp) == (whole.first_stamp, whole.last_stamp), "still matched to its verdict"


def test_one_lost_frame_and_a_slow_idle_camera_before_the_passage_change_nothing():
    whole = measure(set())
    one = measure({5})  # a step of two frame intervals
    assert one.complete and one.nmdm == pytest.approx(whole.nmdm) and one.frames == whole.frames - 1
    after_idle = measure(set(), idle_before=4)  # 0.5 s steps while the view was empty, then the camera's rate
    assert after_idle.complete and after_idle.nmdm == pytest.approx(whole.nmdm, abs=1e-12)


def test_frames_skipped_on_purpose_are_no_gap():
    """A caller that follows the fillet at a slower rate first (the sweeps' side view) says so per frame; the
    same steps unannounced are frames lost."""
    whole = measure(set())
    slow = {i for i in range(1, 16) if i % 4}  # the early frames at a quarter of the rate

    def passage(announced: bool) -> SideMeasurement:
        tracker = SidePassageTracker(AXLE, R, background=SCENE.background())
        out = [m for i, centre in enumerate(disc_passage()) if i not in slow
               for m in tracker.update(with_disc(centre, 20.0), i * DT, planned_step=announced and i - 1 in slow)]
        (m,) = out + flush(tracker, len(disc_passage()) * DT)
        return m

    planned = passage(announced=True)
    assert planned.complete and planned.nmdm == pytest.approx(whole.nmdm, abs=1e-12)
    assert not passage(announced=False).complete


def test_frames_lost_while_the_passage_ends_count_too():
    tracker = SidePassageTracker(AXLE, R, background=SCENE.background())
    for i, centre in enumerate(disc_passage()):
        tracker.update(with_disc(centre, 20.0), i * DT)
    end = len(disc_passage()) * DT
    assert tracker.update(SCENE.background(), end) == []
    (m,) = flush(tracker, end + 1.0)  # frames lost after the disc left: it may have come back in them
    assert not m.complete and math.isnan(m.nmdm)
    tracker.reset()
    assert math.isinf(tracker.interval)
