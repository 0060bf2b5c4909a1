"""Φ on synthetic contours with known geometry: leading-end cut, reference, fixed body span, window, terms.

Flow is +v and the roller edge is the row EDGE; a contour's leading edge is its
max v, its trailing edge its min v. Shapes are drawn as polygons so their width
profile (and so the expected cut) is known exactly.
"""

from __future__ import annotations

import math
from dataclasses import replace

import cv2
import numpy as np
import pytest

from woody_common.line import TOP_CAMERA_HEIGHT_M
from woody_vision.camera_model import LaneLayout
from woody_vision.segmentation import segment_depth
from woody_vision.shape_score import (
    FOREIGN_SHARE,
    LEADING_BLUNT,
    LEADING_NARROW,
    LINE_OVERHANG_FRACTION,
    MIN_SIGHTINGS,
    REASON_LOST_BEFORE_EDGE,
    REASON_LOST_IN_WINDOW,
    REASON_OVERDUE_BEFORE_EDGE,
    REASON_STARTED_PAST_EDGE,
    REASON_WINDOW_GAP,
    STATUS_SCORED,
    STATUS_UNSCORED,
    FrameScore,
    ShapeEvaluator,
    ShapeResult,
    aspect_ratio,
    bracket_at,
    clip_body,
    extrapolate_at,
    fill_rows,
    flat_overlap,
    interpolate_at,
    intruding_share,
    leading_cut_rows,
    leading_end,
    make_reference,
    outside_share,
    own_frames,
    rising_envelope,
    shape_terms,
    solidity,
    touches,
    turn_deg,
)
from woody_vision.synthetic import DEFAULT_TOP_K, TopFillet, TopScene, teardrop_polygon

EDGE = 200.0
FPS = 30.0
LAYOUT3 = LaneLayout(DEFAULT_TOP_K, TOP_CAMERA_HEIGHT_M, 3, 0.16)


def polygon_contour(points) -> np.ndarray:
    return np.round(np.asarray(points, float)).astype(np.int32)


def kite(lead_v: float = 300.0) -> np.ndarray:
    """Narrow tip leading at ``lead_v``, widening over 100 rows to 100 px; 100 rows at full width; a 50-row tail."""
    return polygon_contour([(200, lead_v), (250, lead_v - 100), (250, lead_v - 200), (200, lead_v - 250),
                            (150, lead_v - 200), (150, lead_v - 100)])


def rows_of(contour: np.ndarray) -> tuple[int, int]:
    return int(contour[:, 1].min()), int(contour[:, 1].max())


def translating(frames: int, start_lead_v: float = 120.0, step: float = 3.0, length: float = 110.0,
                width: float = 60.0, bend=None) -> list[np.ndarray]:
    """Contours of a flat teardrop (tip leading) moving down ``step`` px a frame; ``bend(points)`` deforms each."""
    out = []
    for i in range(frames):
        points = teardrop_polygon((300.0, start_lead_v + i * step - length / 2), length, width)
        out.append(polygon_contour(bend(points) if bend else points))
    return out


def foreshorten(factor: float, narrow: float = 0.0):
    """Simulated bending: the part beyond the edge is shortened towards it (and optionally narrowed)."""
    def bend(points: np.ndarray) -> np.ndarray:
        p = points.copy()
        over = p[:, 1] > EDGE
        p[over, 1] = EDGE + (p[over, 1] - EDGE) * factor
        p[over, 0] = 300.0 + (p[over, 0] - 300.0) * (1.0 - narrow)
        return p
    return bend


def blunt_tip_past_the_edge(points: np.ndarray) -> np.ndarray:
    """What the top camera shows of a stiff fillet's thin tip once it is over the floor: the tip ahead of the body
    widens to a blunt 40-px end over its first 6 rows, ahead of the 30 % cut (on the belt it was too thin to
    segment); nothing else changes."""
    p = points.copy()
    lead = p[:, 1].max()
    if lead <= EDGE:
        return p
    tip = p[:, 1] > lead - 6.0
    p[tip, 0] = 300.0 + np.sign(p[tip, 0] - 300.0) * np.maximum(np.abs(p[tip, 0] - 300.0), 20.0)
    return p


def run_evaluator(contours, edge: float = EDGE):
    evaluator = ShapeEvaluator(edge)
    for i, contour in enumerate(contours):
        result = evaluator.update(contour, i / FPS)
        if result is not None:
            return i, result, evaluator
    return None, None, evaluator


# ------------------------------------------------------------------ cut, clip, reference


def test_leading_cut_scans_from_the_leading_end_to_the_first_row_at_30_percent():
    mask, v0, _ = fill_rows(kite(300.0))
    widths = np.count_nonzero(mask, axis=1)
    assert v0 == 50 and widths.size == 251
    # width(v) = 300 - v near the tip: the first row with ≥ 30 px, scanning from v = 300, is v = 270
    assert leading_cut_rows(widths) == pytest.approx(30, abs=1)
    assert leading_cut_rows(widths, tip_ratio=0.5) == pytest.approx(50, abs=1)
    # the trailing tail is narrow too, but only the leading end is ever cut
    assert leading_cut_rows(widths[::-1]) == pytest.approx(15, abs=1)


def test_a_leading_cut_longer_than_half_the_fillet_is_ignored():
    # a wide 40-row trailing lobe ahead of which a 100-row band of 20 px leads: not a tip, an odd outline
    lollipop = polygon_contour([(150, 0), (250, 0), (250, 40), (210, 40), (210, 140), (190, 140), (190, 40),
                                (150, 40)])
    mask, _, _ = fill_rows(lollipop)
    assert leading_cut_rows(np.count_nonzero(mask, axis=1)) == 0
    assert leading_cut_rows(np.zeros(5)) == 0
    reference = make_reference(lollipop)
    assert reference.length_px == 140


def test_clip_body_keeps_exactly_the_span_from_the_trailing_edge():
    contour = kite(300.0)
    body = clip_body(contour, 50, 100)
    assert rows_of(body) == (50, 150)
    assert (body[:, 0].min(), body[:, 0].max()) == (150, 250)
    assert rows_of(clip_body(contour, 50, 1000)) == (50, 300)
    assert clip_body(contour, 400, 10).shape == (0, 2)


def test_reference_cuts_the_leading_tip_once_and_locks_length_offset_ar_solidity():
    reference = make_reference(kite(300.0))
    assert rows_of(reference.body) == (50, pytest.approx(270, abs=1))
    assert reference.length_px == pytest.approx(220, abs=1)
    centroid_v = cv2.moments(reference.body)["m01"] / cv2.moments(reference.body)["m00"]
    assert reference.centroid_offset_px == pytest.approx(centroid_v - 50.0)
    assert reference.aspect_ratio == pytest.approx(aspect_ratio(reference.body))
    assert reference.solidity == pytest.approx(solidity(reference.body))
    assert make_reference(polygon_contour([(0, 0), (10, 0), (20, 0)])) is None


def test_solidity_and_aspect_ratio_of_known_shapes():
    rect = polygon_contour([(0, 0), (100, 0), (100, 50), (0, 50)])
    assert solidity(rect) == pytest.approx(1.0)
    assert aspect_ratio(rect) == pytest.approx(2.0)
    ell = polygon_contour([(0, 0), (100, 0), (100, 50), (50, 50), (50, 100), (0, 100)])
    assert solidity(ell) == pytest.approx(7500 / 8750)
    assert solidity(polygon_contour([(0, 0), (10, 0), (20, 0)])) == 0.0
    assert math.isinf(aspect_ratio(polygon_contour([(0, 0), (10, 0), (20, 0)])))


# ------------------------------------------------------------------ Φ


def test_phi_of_an_unchanged_contour_is_zero():
    index, result, evaluator = run_evaluator(translating(80))
    assert result is not None and result.status == STATUS_SCORED and result.reason == ""
    assert result.frames >= 5 and len(result.trace) == result.frames
    assert result.phi < 1e-6 and result.hu_term < 1e-8 and result.solidity_term < 1e-8
    assert evaluator.done and evaluator.update(translating(1)[0], 99.0) is None and evaluator.finish() is None


def test_phi_grows_monotonically_with_bending():
    flat = teardrop_polygon((300.0, 180.0), 110.0, 60.0)  # body front 20+ px beyond the edge at 200
    reference = make_reference(polygon_contour(flat))
    trailing = int(polygon_contour(flat)[:, 1].min())
    phis = []
    for degrees in (0, 5, 10, 20, 30, 45, 60, 75):
        theta = math.radians(degrees)
        bent = polygon_contour(foreshorten(math.cos(theta), narrow=0.5 * (1.0 - math.cos(theta)))(flat))
        hu, sol = shape_terms(reference, clip_body(bent, trailing, reference.length_px))
        phis.append(100.0 * hu + 100.0 * sol)
    assert phis[0] < 1e-6
    assert all(b > a for a, b in zip(phis, phis[1:])), phis
    assert phis[-1] > 10.0


def test_a_tip_that_only_appears_past_the_edge_does_not_score():
    """The cause of the old k-independent floor: the cut is fixed by the reference, so outline that appears ahead
    of the rigid body front (a thin tip segmented only against the floor) is not part of the body."""
    _, plain, _ = run_evaluator(translating(80))
    _, blunt, _ = run_evaluator(translating(80, bend=blunt_tip_past_the_edge))
    assert blunt.status == STATUS_SCORED and blunt.frames == plain.frames
    assert blunt.phi == pytest.approx(plain.phi, abs=1e-9)
    # the same change re-cut per frame at 30 % of the width would add the tip to the body: a large Φ
    frame = translating(80, bend=blunt_tip_past_the_edge)[40]
    reference = make_reference(translating(80)[0])
    mask, trailing, _ = fill_rows(frame)
    recut = clip_body(frame, trailing, mask.shape[0] - 1 - leading_cut_rows(np.count_nonzero(mask, axis=1)))
    assert 100.0 * sum(shape_terms(reference, recut)) > 5.0


def test_flexible_fillet_scores_clearly_higher_than_a_rigid_one():
    def phi(curvature: float, across: float) -> float:
        scene = TopScene([TopFillet(lead_m=-0.25, across_m=across, curvature_per_m=curvature)])
        background = scene.background_depth()
        evaluator = ShapeEvaluator(scene.edge_row)
        for i in range(60):
            blobs = segment_depth(scene.render(i / FPS)[1], background)
            if blobs:
                result = evaluator.update(blobs[0].contour, i / FPS)
                if result is not None:
                    assert result.status == STATUS_SCORED and result.frames >= 3
                    return result.phi
        raise AssertionError("window never closed")

    for across in (0.0, 0.16):
        rigid, flexible = phi(0.5, across), phi(14.0, across)
        assert flexible > 2.5 * rigid and flexible - rigid > 5.0, (across, rigid, flexible)


def test_terms_are_their_own_maxima_over_the_window():
    def notch_then_shorten(i: int):
        def bend(points: np.ndarray) -> np.ndarray:
            lead = points[:, 1].max()
            if lead - 110.0 + 60.0 < EDGE:  # body front not at the edge yet
                return points
            if i % 2:  # a narrow notch in one side of the flat part: mostly a solidity change
                p = points.copy()
                near = (np.abs(p[:, 1] - (lead - 75.0)) < 3.0) & (p[:, 0] > 300.0)
                p[near, 0] = 300.0 + (p[near, 0] - 300.0) * 0.3
                return p
            return foreshorten(0.3)(points)  # bending: mostly a Hu change
        return bend

    contours = [translating(80, bend=notch_then_shorten(i))[i] for i in range(80)]
    _, result, _ = run_evaluator(contours)
    phis = [f.phi for f in result.trace]
    hus = [f.hu_term for f in result.trace]
    sols = [f.solidity_term for f in result.trace]
    assert result.phi == max(phis) and result.hu_term == max(hus) and result.solidity_term == max(sols)
    assert int(np.argmax(hus)) != int(np.argmax(sols))
    assert result.phi < 100.0 * result.hu_term + 100.0 * result.solidity_term


# ------------------------------------------------------------------ window


def test_window_opens_at_the_rigid_front_and_closes_at_the_virtual_centroid():
    flat = translating(80)
    reference_index = max(i for i, c in enumerate(flat) if c[:, 1].max() < EDGE - 2.0)
    reference = make_reference(flat[reference_index])
    trailing = [int(c[:, 1].min()) for c in flat]
    opens = next(i for i, t in enumerate(trailing) if t + reference.length_px >= EDGE)
    closes = next(i for i, t in enumerate(trailing) if t + reference.centroid_offset_px >= EDGE)
    assert opens > reference_index + 2 and closes > opens + 2
    index, result, _ = run_evaluator(flat)  # decided on the frame after it closes, which confirms the closing one
    assert index == closes + 1 and (closes - 1) / FPS < result.stamp <= closes / FPS  # when its centroid crossed
    assert result.frames == closes - opens + 1
    assert [f.stamp for f in result.trace] == pytest.approx([i / FPS for i in range(opens, closes + 1)])
    assert result.reference_stamp == pytest.approx(reference_index / FPS)

    # Bent over the edge, the body's real centroid lags, but the window still closes on the same frame:
    # the virtual centroid follows the flat trailing edge plus the offset locked while flat.
    bent = translating(80, bend=foreshorten(0.4))
    index_bent, result_bent, _ = run_evaluator(bent)
    assert index_bent == closes + 1 and result_bent.status == STATUS_SCORED and result_bent.phi > 1.0


def test_the_frame_past_the_measuring_point_sets_the_score_only_once_a_later_frame_confirms_it():
    """A stiff fillet whose outline is wrong in the first frame past its measuring point (a neighbour's outline
    joined the hanging part): the next frame caps it, so the score is the clean frames'. A track that ends on
    that frame is scored on the frames it has."""
    contours = translating(80)
    index, clean, _ = run_evaluator(contours)
    past = index - 1
    spoiled = list(contours)
    spoiled[past] = translating(80, bend=foreshorten(0.3))[past]
    index_spoiled, result, _ = run_evaluator(spoiled)
    raw = interpolate_at(list(result.trace + result.extra_trace), clean.line_fraction)[0]
    assert raw > clean.line_phi + 1.0, "precondition: the spoiled frame sets the score unconfirmed"
    assert index_spoiled == index and result.line_phi == pytest.approx(clean.line_phi, abs=0.05)

    ended = ShapeEvaluator(EDGE)
    assert all(ended.update(contour, i / FPS) is None for i, contour in enumerate(spoiled[: past + 1]))
    result = ended.finish()
    assert result.status == STATUS_SCORED and result.line_phi == pytest.approx(raw)


def test_the_flat_part_overlaps_its_reference_moved_with_the_belt_unless_cut_or_joined():
    reference = kite(300.0)
    moved = kite(330.0)
    assert flat_overlap(reference, moved, 30, 320) == pytest.approx(1.0, abs=0.02)
    cut = polygon_contour([(250, 230), (250, 130), (200, 80), (200, 330)])  # its left half: a split took the rest
    assert flat_overlap(reference, cut, 30, 320) < 0.6
    joined = polygon_contour([(150, 330), (250, 230), (250, 130), (200, 80), (120, 130), (120, 330)])
    assert flat_overlap(reference, joined, 30, 320) < 0.8  # a neighbour's strip joined at its side
    assert math.isnan(flat_overlap(reference, moved, 30, 60))  # hardly anything of it left on the belt


def test_a_frame_that_lost_part_of_its_flat_outline_is_rejected_and_never_scores():
    contours = translating(80)
    _, plain, _ = run_evaluator(contours)
    opens = round(plain.trace[0].stamp * FPS)
    piece = contours[opens + 1].copy()
    piece = piece[piece[:, 0] >= 300]  # the right half: a split of a merged blob cut the rest off
    _, result, _ = run_evaluator(contours[:opens + 1] + [piece] + contours[opens + 2:])
    assert result.rejected_frames == plain.rejected_frames + 1 and result.phi == pytest.approx(plain.phi, abs=1e-9)


def test_a_piece_ahead_of_the_fillets_own_trailing_edge_is_rejected_not_a_late_close():
    """A track that took a sliver split off at the edge: its trailing edge leapt ahead of the fillet's."""
    contours = translating(80)
    closes, plain, _ = run_evaluator(contours)
    opens = round(plain.trace[0].stamp * FPS)
    sliver = polygon_contour([(290, EDGE + 5), (310, EDGE + 5), (310, EDGE + 25), (290, EDGE + 25)])
    _, result, evaluator = run_evaluator(contours[:opens + 1] + [sliver] + contours[opens + 2:])
    assert result.status == STATUS_SCORED and result.rejected_frames == plain.rejected_frames + 1
    assert result.line_phi == pytest.approx(plain.line_phi, abs=1e-9)
    trailing = rows_of(contours[closes])[0]
    assert evaluator.predicted_trailing(closes / FPS) == pytest.approx(trailing, abs=1.0)
    assert evaluator.continues_at(trailing + 5, closes / FPS) and not evaluator.continues_at(EDGE + 5, closes / FPS)


def test_the_speed_is_the_fillets_recent_motion_so_a_speed_change_is_followed():
    """3 px a frame for most of the approach, then 4 (the belt sped up): measured at the new speed."""
    leads = [60.0 + 3.0 * i for i in range(30)]
    leads += [leads[-1] + 4.0 * i for i in range(1, 60)]
    contours = [polygon_contour(teardrop_polygon((300.0, lead - 55.0), 110.0, 60.0)) for lead in leads]
    _, result, _ = run_evaluator(contours)
    assert result.speed_px_s == pytest.approx(4.0 * FPS, rel=0.02)


def test_a_degenerate_frame_in_the_window_is_rejected_not_scored():
    contours = translating(80)
    _, plain, _ = run_evaluator(contours)
    opens = round(plain.trace[0].stamp * FPS)
    trailing, leading = rows_of(contours[opens + 1])  # a line over the fillet's own rows: not its flat outline
    line = polygon_contour([(300, trailing), (300, (trailing + leading) / 2), (300, leading)])
    _, result, _ = run_evaluator(contours[:opens + 1] + [line] + contours[opens + 2:])
    assert result.frames == plain.frames - 1 and result.rejected_frames == plain.rejected_frames + 1
    assert result.phi == pytest.approx(plain.phi, abs=1e-9)


def test_a_burst_of_frames_lost_at_the_edge_leaves_the_fillet_unscored_not_misgraded():
    contours = translating(80)
    closes, plain, _ = run_evaluator(contours)
    stamps = list(range(80))
    kept = [i for i in stamps if not closes - 1 <= i <= closes + 3]  # 5 frames lost: the close comes 4 frames late
    evaluator = ShapeEvaluator(EDGE)
    results = [evaluator.update(contours[i], i / FPS) for i in kept]
    (late,) = [r for r in results if r is not None]
    assert late.status == STATUS_UNSCORED and late.reason.startswith("frames lost at the roller edge")
    one_lost = ShapeEvaluator(EDGE)  # one frame lost just before the close: still scored
    results = [one_lost.update(contours[i], i / FPS) for i in stamps if i != closes]
    (scored,) = [r for r in results if r is not None]
    assert plain.status == scored.status == STATUS_SCORED


def test_unscored_when_the_track_starts_past_the_edge_once_seen_three_times():
    evaluator = ShapeEvaluator(EDGE)
    frames = translating(MIN_SIGHTINGS, start_lead_v=EDGE + 5.0)
    *first, result = [evaluator.update(contour, i / FPS) for i, contour in enumerate(frames)]
    assert first == [None] * (MIN_SIGHTINGS - 1), "a piece split off for a frame or two gives no verdict"
    assert result.status == STATUS_UNSCORED and result.reason == REASON_STARTED_PAST_EDGE
    assert math.isnan(result.phi) and math.isnan(result.aspect_ratio) and result.reference_stamp is None
    assert evaluator.finish() is None


def test_unscored_when_the_track_is_lost_in_the_window_or_before_the_body_reaches_the_edge():
    contours = translating(80)
    _, plain, _ = run_evaluator(contours)
    opens = round(plain.trace[0].stamp * FPS)
    evaluator = ShapeEvaluator(EDGE)
    for i in range(opens + 2):
        assert evaluator.update(contours[i], i / FPS) is None
    result = evaluator.finish()
    assert result.status == STATUS_UNSCORED and result.reason == REASON_LOST_IN_WINDOW
    assert result.frames == 2 and result.stamp == pytest.approx(plain.stamp)  # when, by its speed, it crosses
    assert evaluator.finish() is None

    referenced = ShapeEvaluator(EDGE)  # reference locked, body front not at the edge yet
    for i in range(opens):
        referenced.update(contours[i], i / FPS)
    assert referenced.finish().reason == REASON_LOST_BEFORE_EDGE
    early = ShapeEvaluator(EDGE)
    early.update(contours[0], 0.0)
    assert early.finish().reason == REASON_LOST_BEFORE_EDGE


def test_a_fillet_lost_in_its_window_is_overdue_once_its_centroid_is_past_the_edge_by_more_than_a_late_close():
    contours = translating(80)
    _, plain, _ = run_evaluator(contours)
    opens, closes = round(plain.trace[0].stamp * FPS), round(plain.trace[-1].stamp * FPS)
    evaluator = ShapeEvaluator(EDGE)
    for i in range(opens + 2):
        evaluator.update(contours[i], i / FPS)
    assert evaluator.overdue((closes + 1) / FPS) is None  # a frame now could still close the window in time
    result = evaluator.overdue((closes + 3) / FPS)
    assert result.status == STATUS_UNSCORED and result.reason.startswith("no clean frame closed the evaluation window")
    assert abs(result.stamp - plain.trace[-1].stamp) <= 1 / FPS  # stamped when its centroid was due at the edge
    assert evaluator.update(contours[closes + 4], (closes + 4) / FPS) is None and evaluator.finish() is None

    approaching = ShapeEvaluator(EDGE)  # lost on the belt, long before its reference was locked
    for i in range(5):
        approaching.update(contours[i], i / FPS)
    assert approaching.overdue((closes + 3) / FPS).reason == REASON_OVERDUE_BEFORE_EDGE
    assert ShapeEvaluator(EDGE).overdue(1.0) is None  # nothing seen: no speed, no position
    assert run_evaluator(contours)[2].overdue(10.0) is None  # decided already


def test_a_closed_window_whose_measuring_point_no_frame_confirms_is_read_in_time_for_the_gate():
    """The frames after the first one past the measuring point merge with a neighbour's (or go unseen): the
    fillet is read on the frames it has once, by its speed, it lies well past the point, not when its track
    ends half a second later, and stamped when its centroid crossed the edge."""
    contours = translating(80, bend=drooping)
    _, plain, _ = run_evaluator(contours)
    frames = plain.trace + plain.extra_trace
    past = round(next(f for f in frames if f.overhang >= plain.line_fraction).stamp * FPS)
    seen, ended = ShapeEvaluator(EDGE), ShapeEvaluator(EDGE)
    for i in range(past + 1):
        assert seen.update(contours[i], i / FPS) is None and ended.update(contours[i], i / FPS) is None
    assert seen.overdue((past + 1) / FPS) is None  # a confirming frame may still come
    read = seen.overdue((past + 3) / FPS)
    assert read.status == STATUS_SCORED and read.line_phi == pytest.approx(ended.finish().line_phi)
    assert read.stamp == pytest.approx(plain.stamp) and seen.overdue((past + 5) / FPS) is None


def test_evaluator_options_are_validated():
    with pytest.raises(ValueError):
        ShapeEvaluator(EDGE, tip_ratio=1.0)
    with pytest.raises(ValueError):
        ShapeEvaluator(EDGE, reference_margin_px=-1.0)
    with pytest.raises(ValueError):
        ShapeEvaluator(EDGE, tip_ratio=0.0)


# ------------------------------------------------------------------ the line score


def drooping(points: np.ndarray) -> np.ndarray:
    """A compliant fillet: the farther its body overhangs, the more the overhang is foreshortened (continuously)."""
    overhang = max(0.0, points[:, 1].max() - EDGE)
    return foreshorten(1.0 - 0.6 * min(1.0, overhang / 80.0))(points)


def flipped(points: np.ndarray) -> np.ndarray:
    """The same teardrop sent blunt end first (turned 180 degrees about its centre)."""
    centre = (points.max(axis=0) + points.min(axis=0)) / 2.0
    return 2.0 * centre - points


def test_line_phi_does_not_depend_on_where_the_frames_fall_on_the_ramp():
    results = []
    for phase in np.linspace(0.0, 7.0, 8):  # the same fillet, frames falling 0..7 px (of an 8 px step) later
        _, result, _ = run_evaluator(translating(40, start_lead_v=100.0 + phase, step=8.0, bend=drooping))
        results.append(result)
    assert all(r.status == STATUS_SCORED for r in results)
    phis = [r.phi for r in results]
    lines = [r.line_phi for r in results]
    assert np.ptp(lines) < 0.25 * np.ptp(phis) and np.ptp(phis) > 1.0
    assert all(r.leading_end == LEADING_NARROW and r.rejected_frames == 0 for r in results)


def test_a_blunt_first_fillet_is_measured_at_the_same_overhang_after_its_window_closes():
    contours = [polygon_contour(flipped(c.astype(float))) for c in translating(120)]
    closes, result, _ = run_evaluator([polygon_contour(drooping(c.astype(float))) for c in contours])
    assert result.status == STATUS_SCORED and result.leading_end == LEADING_BLUNT
    assert result.extra_trace and result.extra_trace[-1].overhang >= LINE_OVERHANG_FRACTION
    assert result.trace[-1].overhang < LINE_OVERHANG_FRACTION  # the paper's window closed before half overhung
    assert leading_end(contours[0]) == LEADING_BLUNT and leading_end(translating(1)[0]) == LEADING_NARROW


@pytest.mark.parametrize("turn", [-45, -40, -32, 0, 32, 40, 45])
@pytest.mark.parametrize("narrow_first", [True, False])
def test_the_leading_end_is_read_along_the_fillets_own_axis_up_to_the_largest_turn(turn, narrow_first):
    """A wide fillet turned 40 degrees: image rows cut across both ends, its long axis does not."""
    outline = teardrop_polygon((300.0, 200.0), 100.0, 70.0, tip_down=narrow_first)
    angle = math.radians(turn)
    rotation = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    turned = np.round((outline - (300.0, 200.0)) @ rotation.T + (300.0, 200.0)).astype(np.int32)
    assert leading_end(turned) == (LEADING_NARROW if narrow_first else LEADING_BLUNT)


def filled(*contours: np.ndarray) -> np.ndarray:
    """A mask with the contours filled in."""
    mask = np.zeros((800, 800), np.uint8)
    cv2.fillPoly(mask, list(contours), 255)
    return mask


def outline_of(mask: np.ndarray) -> np.ndarray:
    """The outline of the mask's largest blob."""
    outline, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    return max(outline, key=cv2.contourArea).reshape(-1, 2)


def merged_with_follower(contour: np.ndarray, gap_px: int = 0) -> np.ndarray:
    """The blob of a fillet and an identical follower touching it from behind, as one contour."""
    length = int(np.ptp(contour[:, 1]))
    return outline_of(filled(contour, contour - (0, length - gap_px)))


def test_a_window_frame_merged_with_the_follower_is_rejected_not_scored():
    contours = translating(90, bend=drooping)
    _, plain, _ = run_evaluator(contours)
    opens = round(plain.trace[0].stamp * FPS)
    crowded = list(contours)
    crowded[opens + 2] = merged_with_follower(contours[opens + 2])
    _, result, _ = run_evaluator(crowded)
    assert result.rejected_frames == 1 and result.frames == plain.frames - 1
    assert result.phi == pytest.approx(plain.phi) and result.line_phi == pytest.approx(plain.line_phi)


def with_box(contour: np.ndarray, u0: int, v0: int, u1: int, v1: int) -> np.ndarray:
    """One outline of the contour's area and a box joined to it."""
    mask = filled(contour)
    cv2.rectangle(mask, (int(u0), int(v0)), (int(u1), int(v1)), 255, -1)
    return outline_of(mask)


def test_a_window_frame_reaching_beyond_the_fillets_columns_or_length_is_rejected():
    """Bending over the roller only shortens a fillet along the flow on the belt plane: more is another's."""
    contours = translating(90, bend=drooping)
    _, plain, _ = run_evaluator(contours)
    opens = round(plain.trace[0].stamp * FPS)
    lead = rows_of(contours[opens + 2])[1]
    crowded = list(contours)
    crowded[opens + 1] = with_box(contours[opens + 1], 300, EDGE + 2, 345, EDGE + 8)  # a neighbour's rim beside
    crowded[opens + 2] = with_box(contours[opens + 2], 297, lead - 2, 303, lead + 20)  # the lane-mate hanging ahead
    _, result, _ = run_evaluator(crowded)
    assert result.rejected_frames == plain.rejected_frames + 2
    assert result.line_phi == pytest.approx(plain.line_phi)


def test_a_bending_fillet_stays_in_its_footprint_riding_the_belt_and_a_neighbours_piece_does_not():
    """On the belt plane bending over the roller only shortens a fillet along the flow, part by part in its own
    columns: what its outline covers outside its footprint moved with the belt is another fillet's."""
    flat, bent = translating(1)[0], translating(1, bend=foreshorten(0.5))[0]
    moved = flat + (0, 40)
    assert outside_share(flat, flat, 0) == 0.0 and outside_share(flat, bent, 0) == 0.0
    assert outside_share(flat, moved, 40) == 0.0 and outside_share(flat, moved, 0) > FOREIGN_SHARE
    trailing = rows_of(bent)[0]
    assert outside_share(flat, with_box(bent, 300, trailing, 328, trailing + 6), 0) > FOREIGN_SHARE


def test_a_window_frame_holding_a_neighbours_piece_within_its_columns_and_length_is_rejected():
    """A neighbour's hanging part joined beside the fillet's round trailing end: no wider, no longer, a little larger
    and with its own trailing edge, so only the footprint tells it is not this fillet's."""
    contours = translating(90, bend=drooping)
    _, plain, _ = run_evaluator(contours)
    opens = round(plain.trace[0].stamp * FPS)
    crowded = list(contours)
    trailing = rows_of(contours[opens + 1])[0]
    crowded[opens + 1] = with_box(contours[opens + 1], 300, trailing, 328, trailing + 6)
    _, result, _ = run_evaluator(crowded)
    assert result.rejected_frames == plain.rejected_frames + 1 and result.frames == plain.frames - 1, "never scored"
    assert result.line_phi == pytest.approx(plain.line_phi)


def cut_by_a_neighbour(contour: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """The contour with the right side of its part past the edge handed to a neighbour by a split of their joined
    blob, and that neighbour's outline (its hanging part joined with the piece); no neighbour before the edge."""
    mask = filled(contour)
    stolen = np.zeros_like(mask)
    stolen[int(EDGE) + 1:, 312:] = 255
    piece = cv2.bitwise_and(mask, stolen)
    if cv2.countNonZero(piece) < 20:
        return contour, []
    neighbour = cv2.bitwise_or(piece, cv2.bitwise_and(stolen, cv2.rectangle(np.zeros_like(mask), (331, int(EDGE) + 1),
                                                                            (370, 800), 255, -1)))
    return outline_of(cv2.bitwise_and(mask, cv2.bitwise_not(stolen))), [outline_of(neighbour)]


def test_a_frame_a_neighbours_outline_cut_a_piece_from_is_rejected_near_the_measuring_point():
    """The split of a joined blob gave the neighbour a piece of this fillet's hanging part: this fillet's outline
    misses it (its Φ_t rises as if it bent) and the neighbour's reaches into this fillet's footprint, which no
    fillet's own outline does. Such frames never set the line score."""
    flat, contours = translating(90), translating(90, bend=drooping)
    _, plain, _ = run_evaluator(contours)
    assert intruding_share(flat[60], hugging(flat[60], EDGE - 30), 0, 800) == 0.0, "a neighbour beside is none"
    def graded(with_neighbours: bool) -> ShapeResult:
        evaluator, results = ShapeEvaluator(EDGE), []
        for i, contour in enumerate(contours):
            own, neighbours = cut_by_a_neighbour(contour)
            results.append(evaluator.update(own, i / FPS, neighbours=neighbours if with_neighbours else []))
        (result,) = [r for r in results if r is not None]
        return result
    assert graded(False).line_phi > 1.2 * plain.line_phi, "precondition: the cut outline scores as if it bent more"
    cut = graded(True)
    assert cut.status == STATUS_UNSCORED and cut.rejected_frames > plain.rejected_frames


def hugging(contour: np.ndarray, first_row: float) -> np.ndarray:
    """A neighbour's outline lying against the contour's right side from ``first_row`` on: a 40 px band whose left
    side follows the contour's 2 px away."""
    side = contour[(contour[:, 0] > 300) & (contour[:, 1] >= first_row)]
    side = side[np.argsort(side[:, 1], kind="stable")] + np.array([2, 0], np.int32)
    return np.concatenate([side, side[::-1] + np.array([40, 0], np.int32)])


def test_touching_is_a_shared_boundary_of_enough_points():
    fillet = translating(1, start_lead_v=EDGE + 60.0)[0]
    assert touches(fillet, [hugging(fillet, EDGE)])
    assert touches(fillet, [hugging(fillet, EDGE - 60.0)])  # on the belt as over the roller
    assert not touches(fillet, [hugging(fillet, EDGE) + np.array([3, 0], np.int32)])  # a gap between
    assert not touches(fillet, [hugging(fillet, EDGE)[:3]])  # a corner, not a shared boundary
    assert not touches(fillet, [])


def test_frames_split_from_a_neighbour_at_the_measuring_point_are_scored_and_marked():
    contours = translating(90, bend=drooping)
    _, plain, _ = run_evaluator(contours)
    evaluator = ShapeEvaluator(EDGE)
    flat = translating(90)  # the neighbour lies beside the fillet's footprint, never inside it
    results = [evaluator.update(c, i / FPS, neighbours=[hugging(f, EDGE - 30)])
               for i, (c, f) in enumerate(zip(contours, flat))]
    (joined,) = [r for r in results if r is not None]
    assert joined.joined_at_line and not plain.joined_at_line
    assert joined.line_phi == pytest.approx(plain.line_phi) and joined.rejected_frames == plain.rejected_frames


def test_a_fillet_merged_at_its_measuring_point_is_unscored_with_the_reason():
    contours = translating(90, bend=drooping)
    closes, plain, _ = run_evaluator(contours)
    crowded = [merged_with_follower(c) if closes - 3 <= i < closes else c for i, c in enumerate(contours)]
    _, result, _ = run_evaluator(crowded)
    assert result.status == STATUS_UNSCORED and result.rejected_frames == 3
    assert result.reason.startswith("no clean frames around the measuring point")


def trace(*pairs) -> list[FrameScore]:
    """Window frames of (overhang, Φ_t) pairs, one a frame apart."""
    return [FrameScore(i / FPS, phi, math.nan, math.nan, overhang) for i, (overhang, phi) in enumerate(pairs)]


def test_a_fillet_merged_just_before_its_measuring_point_is_scored_from_the_clean_frames_past_it():
    """Two side-by-side fillets merge for a few frames as they tip: the frames left before the point are too far
    back, but the first clean frame past it lies within a frame's advance, so the line through it and the next one
    reads the point."""
    contours = translating(90, bend=drooping)
    _, plain, _ = run_evaluator(contours)
    frames = plain.trace + plain.extra_trace
    past = next(i for i, f in enumerate(frames) if f.overhang >= plain.line_fraction)
    first = round(frames[past].stamp * FPS)
    crowded = [merged_with_follower(c) if first - 3 <= i < first else c for i, c in enumerate(contours)]
    _, result, _ = run_evaluator(crowded)
    assert result.status == STATUS_SCORED and result.rejected_frames == 3
    assert result.line_phi == pytest.approx(plain.line_phi, rel=0.05)


def test_extrapolation_takes_the_nearer_side_within_a_frame_and_never_across_a_gap():
    assert extrapolate_at(trace((0.1, 1.0), (0.2, 2.0), (0.55, 6.0), (0.65, 8.0)), 0.5, 0.1) == (
        pytest.approx(5.0), 2)
    assert extrapolate_at(trace((0.35, 3.0), (0.45, 4.0), (0.8, 9.0), (0.9, 11.0)), 0.5, 0.1) == (
        pytest.approx(4.5), 1)
    assert math.isnan(extrapolate_at(trace((0.1, 1.0), (0.2, 2.0), (0.65, 8.0), (0.75, 9.0)), 0.5, 0.1)[0])
    assert extrapolate_at(trace((0.2, 1.0), (0.55, 6.0), (0.9, 8.0)), 0.5, 0.1)[1] is None
    assert extrapolate_at(trace((0.1, 0.1), (0.58, 0.2), (0.62, 3.0)), 0.5, 0.1) == (0.0, 1)  # never below 0


def test_the_frames_on_either_side_of_a_point_bound_its_score_however_far_apart():
    frames = rising_envelope(trace((0.1, 1.0), (0.3, 4.0), (0.8, 6.0), (0.9, 5.0)))
    assert bracket_at(frames, 0.5) == (4.0, 5.0)  # the frame at 0.8 lowered to the one after it
    assert bracket_at(frames, 0.05) == (0.0, 1.0) and bracket_at(frames, 0.95) == (5.0, math.inf)
    assert bracket_at(frames, 0.3) == (4.0, 4.0)
    joined = [replace(f, joined=f.overhang == 0.3) for f in frames]
    assert bracket_at(joined, 0.5) == (1.0, 5.0), "a joined frame bounds the score from above only"
    assert bracket_at(joined, 0.2) == (1.0, 4.0)


def test_a_frame_the_envelope_lowers_by_more_than_half_is_dropped_and_a_small_dip_is_kept():
    kept, own = own_frames(trace((0.33, 1.3), (0.45, 17.9), (0.71, 5.1), (0.89, 6.2)))
    assert kept == [0, 2, 3] and [f.phi for f in own] == [1.3, 5.1, 6.2]
    kept, own = own_frames(trace((0.3, 2.0), (0.4, 1.8), (0.5, 2.5)))
    assert kept == [0, 1, 2] and [f.phi for f in own] == [1.8, 1.8, 2.5]
    kept, _ = own_frames(trace((0.3, 0.4), (0.4, 0.1), (0.5, 0.2)))  # a flat fillet's near-zero Φ_t
    assert kept == [0, 1, 2]


def test_the_reference_skips_a_flat_frame_merged_with_a_neighbour():
    contours = translating(90)
    _, plain, _ = run_evaluator(contours)
    reference_index = round(plain.reference_stamp * FPS)
    crowded = list(contours)
    crowded[reference_index] = merged_with_follower(contours[reference_index])
    _, result, _ = run_evaluator(crowded)
    assert result.reference_stamp == pytest.approx((reference_index - 1) / FPS)
    assert result.status == STATUS_SCORED and result.phi == pytest.approx(plain.phi, abs=0.5)


def test_the_turn_from_the_flow_is_read_off_the_outline():
    straight = translating(1)[0].astype(float)
    centre = straight.mean(axis=0)
    for degrees in (0.0, 15.0, -30.0):
        angle = math.radians(degrees)
        rotation = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
        turned = polygon_contour((straight - centre) @ rotation.T + centre)
        assert turn_deg(turned) == pytest.approx(abs(degrees), abs=1.5)


def test_frames_of_a_track_that_switched_to_the_neighbour_are_rejected():
    """After a merge a track can follow the fillet in the next lane: its outline is clean but a width across."""
    contours = translating(90, bend=drooping)
    closes, plain, _ = run_evaluator(contours)
    opens = round(plain.trace[0].stamp * FPS)
    switched = [c + (70, 0) if i >= opens else c for i, c in enumerate(contours)]
    _, result, evaluator = run_evaluator(switched)
    assert result is None  # no clean frame closes the window: the fillet waits for its track to end
    ended = evaluator.finish()
    assert ended.status == STATUS_UNSCORED and ended.rejected_frames == len(switched) - opens


# ------------------------------------------------------------------ frames lost in the window


def run_without(contours, lost: set[int], edge: float = EDGE):
    """The evaluator fed every frame but the ``lost`` ones, each at its own stamp; the result."""
    evaluator = ShapeEvaluator(edge)
    results = [evaluator.update(c, i / FPS) for i, c in enumerate(contours) if i not in lost]
    (result,) = [r for r in results if r is not None]
    return result


def test_frames_lost_inside_the_window_leave_phi_absent_with_the_reason_and_keep_the_line_score():
    contours = translating(80, bend=drooping)
    _, whole, _ = run_evaluator(contours)
    opens, closes = (round(f.stamp * FPS) for f in (whole.trace[0], whole.trace[-1]))
    assert closes - opens >= 4 and whole.reason == "" and math.isfinite(whole.phi) and whole.window_closed
    gap = run_without(contours, {opens + 1, opens + 2})  # two frames in a row: a step of 3 frame intervals
    assert gap.status == STATUS_SCORED and gap.reason == REASON_WINDOW_GAP.format(3 / FPS)
    assert math.isnan(gap.phi) and math.isnan(gap.hu_term) and math.isnan(gap.solidity_term)
    assert not gap.window_closed
    assert gap.line_phi == pytest.approx(whole.line_phi, abs=1e-9)  # measured at its own moment, frames around it
    assert gap.stamp == whole.stamp


def test_one_lost_frame_or_frames_lost_before_the_window_change_nothing():
    contours = translating(80, bend=drooping)
    _, whole, _ = run_evaluator(contours)
    opens = round(whole.trace[0].stamp * FPS)
    one = run_without(contours, {opens + 1})  # a step of 2 frame intervals is no gap
    assert one.reason == "" and one.window_closed and math.isfinite(one.phi)
    assert one.phi == pytest.approx(max(f.phi for f in whole.trace if f.stamp != (opens + 1) / FPS), abs=1e-9)
    early = run_without(contours, {opens - 8, opens - 7, opens - 6})  # lost while flat, long before the window
    assert (early.status, early.reason, early.phi, early.line_phi) == (whole.status, "", whole.phi, whole.line_phi)



def test_the_papers_phi_is_measured_on_the_image_outline_and_the_line_score_on_the_followed_one():
    """The belt outline decides the window and line_phi; the outline in the image gives Φ and its terms."""
    belt = translating(80, bend=foreshorten(0.5))
    image = translating(80)  # a camera that happens to see no change: Φ of the image outline is 0
    evaluator = ShapeEvaluator(EDGE)
    result = next(r for i, (b, m) in enumerate(zip(belt, image)) if (r := evaluator.update(b, i / FPS, m)))
    _, alone, _ = run_evaluator(belt)
    assert result.status == "scored" and result.window_closed
    assert result.line_phi == pytest.approx(alone.line_phi) and result.line_phi > 1.0
    assert result.phi < 1e-6 and alone.phi > 1.0
    assert len(result.paper_trace) == len(result.trace) and alone.paper_trace == alone.trace


def test_frames_a_neighbour_joined_never_set_the_line_score_and_a_ramp_is_kept():
    """The frames of a stiff fillet around its measuring point, with a neighbour's outline joined to it in one
    frame (11.6 among 1.4 and 1.8), or in two (15.4, 10.8 before 2.6): the line score is the clean frames' value.
    A drooping fillet's steep ramp is left exactly as it was."""
    def frames(phis):
        return [FrameScore(stamp=i / 30.0, phi=phi, hu_term=0.0, solidity_term=0.0, overhang=0.35 + 0.1 * i)
                for i, phi in enumerate(phis)]

    for phis, clean in (([0.5, 0.3, 0.4, 1.4, 11.6, 1.8], (1.4, 1.8)), ([0.3, 0.4, 15.4, 10.8, 2.6], (0.4, 2.6))):
        assert interpolate_at(frames(phis), 0.72)[0] > 5.0, "precondition: the joined frames set the raw score"
        assert clean[0] <= interpolate_at(rising_envelope(frames(phis)), 0.72)[0] <= clean[1]
    ramp = frames([1.0, 1.5, 2.5, 6.0, 12.0, 19.0])
    assert [f.phi for f in rising_envelope(ramp)] == [f.phi for f in ramp]
    assert math.isnan(rising_envelope(frames([2.0, math.nan, 3.0]))[1].phi)
