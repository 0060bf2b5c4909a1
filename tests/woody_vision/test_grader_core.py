"""FilletGrader: one verdict per fillet at its window's close, and the watched lane's side results apart."""

from __future__ import annotations

import math

import numpy as np
import pytest

from woody_vision.frame_checks import GAP_FRAMES
from woody_vision.grader_core import (
    JOINED_MARGIN_LN,
    JOINED_MERGED_FRAMES,
    PIECE_REASONS,
    REASON_BOUND,
    REASON_NO_SIDE,
    SIDE_MATCH_SLACK_S,
    SIDE_SILENT_S,
    FilletGrader,
    GradedFillet,
    SideResult,
    TrackObservation,
)
from woody_vision.grading import FittedRange, GradingRules
from woody_vision.shape_score import (
    MIN_SIGHTINGS,
    REASON_LOST_BEFORE_EDGE,
    REASON_LOST_IN_WINDOW,
    REASON_STARTED_PAST_EDGE,
    STATUS_SCORED,
)
from woody_vision.side_view import SideMeasurement
from woody_vision.synthetic import teardrop_polygon

EDGE = 200.0
FPS = 30.0
WAIT = 0.8
WATCHED = 1


def contours(frames: int = 90, start_tip_v: float = 120.0, step: float = 3.0, bend: float = 1.0,
             narrow_first: bool = True) -> list[np.ndarray]:
    """A teardrop moving down through the edge row; ``bend`` < 1 shortens the part beyond the edge (flexible)."""
    out = []
    for i in range(frames):
        p = teardrop_polygon((300.0, start_tip_v + i * step - 55.0), 110.0, 60.0, tip_down=narrow_first)
        over = p[:, 1] > EDGE
        p[over, 1] = EDGE + (p[over, 1] - EDGE) * bend
        out.append(np.round(p).astype(np.int32))
    return out


def side(first: float, last: float, nmdm: float = 0.5) -> SideMeasurement:
    return SideMeasurement(nmdm=nmdm, mdm_min_px=30.0, be=20.0, h_px=12.0, stamp_of_min=(first + last) / 2,
                           first_stamp=first, last_stamp=last, frames=10)


def feed(grader: FilletGrader, track_id: int, lane: int, shapes, t0: float = 0.0, end: bool = False,
         extra_after: int = 0) -> list[tuple[float, GradedFillet]]:
    """Feed one track frame by frame; returns (stamp, verdict) for every verdict that came out."""
    out = []
    stamp = t0
    for i, contour in enumerate(shapes):
        stamp = t0 + i / FPS
        out += [(stamp, g) for g in grader.on_tracks(stamp, [TrackObservation(track_id, lane, contour)])]
    for j in range(extra_after):  # stale frames of the same track (unseen) and empty frames
        stamp += 1 / FPS
        stale = TrackObservation(track_id, lane, shapes[-1], unseen=j + 1)
        out += [(stamp, g) for g in grader.on_tracks(stamp, [stale])]
    if end:
        stamp += 1 / FPS
        out += [(stamp, g) for g in grader.on_tracks(stamp, [], ended_ids=[track_id])]
    return out


def crossed_just_before(published: float, verdict: GradedFillet) -> bool:
    """Whether the verdict, published on the frame at ``published``, is stamped with its fillet's crossing of the
    edge at most two frames before: on the closing frame's or the one before it."""
    return 0.0 <= published - verdict.shape.stamp <= 2 / FPS


def whole_verdict(shapes, t0: float = 0.0) -> GradedFillet:
    """The verdict of a fresh grader fed every frame of ``shapes``."""
    ((_, verdict),) = feed(FilletGrader(EDGE), 0, 0, shapes, t0)
    return verdict


def closing_stamp(shapes, t0: float = 0.0) -> float:
    return whole_verdict(shapes, t0).shape.stamp


def opening_frame(shapes) -> int:
    """The index of the first frame of the window: the frames before its measuring point follow it."""
    return int(round(whole_verdict(shapes).shape.trace[0].stamp * FPS))


def through_close(shapes, extra: int = 3) -> list[np.ndarray]:
    """The frames up to the one that closes the window, plus ``extra`` more (well within the side wait)."""
    return shapes[: int(round(closing_stamp(shapes) * FPS)) + 1 + extra]


def test_one_verdict_per_track_even_with_frames_after_the_window_closed():
    grader = FilletGrader(EDGE, GradingRules(threshold=1.0))
    shapes = contours(120)  # keeps coming long after the window closed
    out = feed(grader, 7, 0, shapes, end=True, extra_after=5)
    assert len(out) == 1
    stamp, verdict = out[0]
    assert verdict.fillet_id == 7 and verdict.lane == 0 and verdict.scored
    assert verdict.shape.status == STATUS_SCORED and stamp < 90 / FPS and crossed_just_before(stamp, verdict)
    assert verdict.label == "woody" and verdict.shape.phi < 1e-6  # unchanged outline: stiff
    assert grader.release(1e9) == []


def test_classification_follows_the_rules():
    rules = GradingRules(threshold=1.0, severe_threshold=0.5)
    grader = FilletGrader(EDGE, rules)
    ((_, flexible),) = feed(grader, 1, 0, contours(90, bend=0.4))
    ((_, stiff),) = feed(grader, 2, 2, contours(90))
    assert flexible.shape.phi > 1.0 and flexible.label == "normal"
    assert flexible.grade == rules.grade(flexible.shape.phi)
    assert stiff.label == "woody" and stiff.grade == "severe"
    assert FilletGrader(EDGE).on_tracks(0.0, []) == []


def test_a_fillet_measured_outside_the_fitted_range_is_unscored_unless_asked():
    slow = FittedRange(0.4, 0.8, 40.0, 0.0, 10.0)  # the contours move 90 px/s: 0.9 m/s at 100 px/m
    ((_, outside),) = feed(FilletGrader(EDGE, GradingRules(1.0), pixels_per_metre=100.0, fitted_range=slow), 1, 0,
                           contours(90))
    assert outside.label == "unscored" and not outside.scored and outside.grade == ""
    assert outside.reason.startswith("outside the calibration: measured speed 0.90 m/s")
    ((_, graded),) = feed(FilletGrader(EDGE, GradingRules(1.0), pixels_per_metre=100.0, fitted_range=None), 1, 0,
                          contours(90))
    assert graded.label == "woody" and graded.scored


def test_unscored_verdict_when_the_track_ends_in_the_window():
    grader = FilletGrader(EDGE, watched_lane=WATCHED)
    shapes = contours(90)
    window_opens = opening_frame(shapes)
    out = feed(grader, 3, WATCHED, shapes[: window_opens + 3], end=True)  # lost long before its measuring point
    ((_, verdict),) = out
    assert verdict.label == "unscored" and verdict.grade == "" and not verdict.scored
    assert verdict.shape.reason == REASON_LOST_IN_WINDOW and verdict.lane == WATCHED
    (result,) = grader.release(1e9)  # an unscored watched-lane fillet still gets its side result
    assert result.fillet_id == 3 and result.stamp == verdict.shape.stamp and result.side is None


def test_a_fillet_its_track_lost_in_the_window_gets_its_verdict_in_time_for_the_gate_not_when_the_track_ends():
    grader = FilletGrader(EDGE)
    shapes = contours(90)
    closes = closing_stamp(shapes)
    out = feed(grader, 3, 0, shapes[: opening_frame(shapes) + 3], end=True, extra_after=40)
    ((published, verdict),) = out  # the tracker ends the track 40 frames later: no second verdict then
    assert verdict.label == "unscored" and verdict.reason.startswith("no clean frame closed the evaluation window")
    assert published <= closes + (GAP_FRAMES + 1) / FPS
    assert verdict.shape.stamp == pytest.approx(closes, abs=1 / FPS)  # stamped when its centroid was due at the edge


def test_a_piece_split_off_past_the_edge_gets_no_verdict_but_a_fillet_appearing_there_alone_does():
    grader = FilletGrader(EDGE, GradingRules(threshold=1.0))
    shapes = contours(90)
    piece = np.array([[290, 205], [310, 205], [310, 225], [290, 225]], np.int32)
    for i, contour in enumerate(shapes[:30]):  # seen flat, then at the edge: its reference is locked
        assert grader.on_tracks(i / FPS, [TrackObservation(1, 0, contour)]) == []
    for i in range(30, 30 + MIN_SIGHTINGS):
        assert grader.on_tracks(i / FPS, [TrackObservation(1, 0, shapes[i]), TrackObservation(2, 0, piece)]) == []
    assert grader.fragments == 1
    ((_, alone),) = feed(FilletGrader(EDGE), 3, 1, [piece] * MIN_SIGHTINGS)  # nothing in its lane: heard
    assert alone.label == "unscored" and alone.shape.reason == REASON_STARTED_PAST_EDGE


def sliver_window(grader: FilletGrader, lane: int, past_edge_px: float = 12.0,
                  merged: frozenset[int] = frozenset()) -> list[GradedFillet]:
    """Track 2, a sliver a split gave a track of its own, rides beside lane 0's fillet (track 1) from before the
    edge until its track ends with its front ``past_edge_px`` past the edge (inside its window by default), merged
    with a neighbour in the ``merged`` frames; track 1 goes on."""
    out, ended = [], False
    for i, contour in enumerate(contours(60)):
        sliver = np.round(teardrop_polygon((380.0, contour[:, 1].min() + 30.0), 30.0, 16.0)).astype(np.int32)
        seen = sliver[:, 1].max() < EDGE + past_edge_px
        sliver = widened(sliver) if i in merged else sliver
        observed = [TrackObservation(1, 0, contour)] + ([TrackObservation(2, lane, sliver)] if seen else [])
        out += grader.on_tracks(i / FPS, observed, ended_ids=[2] if not (seen or ended) else [])
        ended = ended or not seen
    return [g for g in out if g.fillet_id == 2]


def test_a_sliver_that_opened_a_window_beside_its_lanes_fillet_gets_no_verdict_but_one_alone_does():
    grader = FilletGrader(EDGE, GradingRules(threshold=1.0))
    assert sliver_window(grader, lane=0) == [] and grader.fragments == 1
    (alone,) = sliver_window(FilletGrader(EDGE, GradingRules(threshold=1.0)), lane=1)
    assert alone.label == "unscored" and alone.shape.reference_contour is not None  # no fillet in its lane: heard
    assert alone.shape.reason not in PIECE_REASONS


def test_a_sliver_whose_window_is_read_as_a_bound_beside_its_lanes_fillet_gets_no_verdict():
    (scored,) = sliver_window(FilletGrader(EDGE, GradingRules(threshold=1.0)), lane=1, past_edge_px=40.0)
    frames = scored.shape.trace + scored.shape.extra_trace
    point = round(next(f for f in frames if f.overhang >= scored.shape.line_fraction).stamp * FPS)
    merged = frozenset(range(point - 4, point + 2))  # too far apart to read the point, but its Φ_t is ~0: woody
    (alone,) = sliver_window(FilletGrader(EDGE, GradingRules(threshold=1.0)), 1, 40.0, merged)
    assert alone.label == "woody" and alone.reason.startswith("line score read as a bound")
    beside = FilletGrader(EDGE, GradingRules(threshold=1.0))
    assert sliver_window(beside, 0, 40.0, merged) == [] and beside.fragments == 1


def test_a_whole_fillet_unscored_beside_a_lane_mate_joined_to_its_neighbour_gets_its_verdict():
    """Lane 0's track 1 is two touching fillets' joined blob, 2.4 times a fillet's area; track 2, a whole fillet of
    that lane, ends inside its window. Against fillets of other lanes, track 1's outline is no fillet's size."""
    def whole_fillet_verdicts(others: int) -> list[GradedFillet]:
        grader, out, ended = FilletGrader(EDGE, GradingRules(threshold=1.0)), [], False
        for i, contour in enumerate(contours(60)):
            seen, beside = contour[:, 1].max() < EDGE + 12, contour + np.int32([200, 0])
            observed = [TrackObservation(1, 0, widened(contour, 2.4))]
            observed += [TrackObservation(2 + lane, lane, beside) for lane in range(1, others + 1)]
            observed += [TrackObservation(2, 0, contour + np.int32([-200, 0]))] if seen else []
            out += grader.on_tracks(i / FPS, observed, ended_ids=[2] if not (seen or ended) else [])
            ended = ended or not seen
        return [g for g in out if g.fillet_id == 2]
    (verdict,) = whole_fillet_verdicts(others=2)
    assert verdict.label == "unscored" and verdict.reason == REASON_LOST_IN_WINDOW
    assert whole_fillet_verdicts(others=0) == []  # nothing tells the joined blob from a fillet: a piece of it


def test_a_sliver_that_scored_a_window_outside_the_calibration_beside_its_lanes_fillet_gets_no_verdict():
    """Its score would make it unscored (a sliver is shorter than any fillet the cuts were fitted on, or turned
    past them): a piece, like a sliver whose window did not close."""
    fitted = FittedRange(0.5, 1.5, 45.0, 0.5, 2.0)  # at 100 px/m the fillet is 1.1 m long, the sliver 0.3 m
    def grader():
        return FilletGrader(EDGE, GradingRules(threshold=1.0), pixels_per_metre=100.0, fitted_range=fitted)
    beside = grader()
    assert sliver_window(beside, lane=0, past_edge_px=40.0) == [] and beside.fragments == 1
    (alone,) = sliver_window(grader(), lane=1, past_edge_px=40.0)
    assert alone.label == "unscored" and alone.reason.startswith("outside the calibration: measured body length")


def test_a_fillet_first_seen_past_the_edge_beside_its_lane_neighbour_gets_its_unscored_verdict():
    """A fillet hidden in its neighbour's blob until the edge is not a piece: the gate must hear of it."""
    grader = FilletGrader(EDGE, GradingRules(threshold=1.0))
    shapes = contours(90)
    for i, contour in enumerate(shapes[:30]):
        assert grader.on_tracks(i / FPS, [TrackObservation(1, 0, contour)]) == []
    hidden = contours(1, start_tip_v=EDGE + 60.0)[0]  # a whole fillet's outline, already past the edge
    verdicts = [grader.on_tracks(i / FPS, [TrackObservation(1, 0, shapes[i]), TrackObservation(2, 0, hidden)])
                for i in range(30, 30 + MIN_SIGHTINGS)]
    assert verdicts[:-1] == [[]] * (MIN_SIGHTINGS - 1), "heard once it is seen as often as any fillet"
    (verdict,) = verdicts[-1]
    assert verdict.fillet_id == 2 and verdict.label == "unscored" and verdict.shape.reason == REASON_STARTED_PAST_EDGE
    assert grader.fragments == 0


def lost_at_the_edge(grader: FilletGrader, shapes, handover: int) -> list[GradedFillet]:
    """Track 1 follows the fillet up to frame ``handover``, where it takes a sliver split off past the edge and
    the fillet's own outline opens track 2, which follows it to the end."""
    sliver = np.array([[320, 205], [335, 205], [335, 220], [320, 220]], np.int32)
    out = []
    for i, contour in enumerate(shapes):
        if i < handover:
            observed = [TrackObservation(1, 0, contour)]
        else:
            observed = [TrackObservation(1, 0, sliver, unseen=int(i > handover)), TrackObservation(2, 0, contour)]
        out += grader.on_tracks(i / FPS, observed)
    return out + grader.on_tracks(len(shapes) / FPS, [], ended_ids=[1, 2])


def test_a_fillet_its_track_lost_at_the_edge_gets_one_verdict_from_the_track_that_found_it_again():
    shapes = contours(90)
    ((_, plain),) = feed(FilletGrader(EDGE, GradingRules(threshold=1.0)), 1, 0, shapes, end=True)
    closes = round(plain.shape.stamp * FPS)
    grader = FilletGrader(EDGE, GradingRules(threshold=1.0))
    (verdict,) = lost_at_the_edge(grader, shapes, handover=closes - 2)  # in the window, before it closes
    assert verdict.fillet_id == 2 and verdict.scored and verdict.shape.line_phi == plain.shape.line_phi
    assert verdict.shape.rejected_frames == 1 and grader.taken_over == 1  # the sliver frame track 1 took
    late = FilletGrader(EDGE, GradingRules(threshold=1.0))
    (verdict,) = lost_at_the_edge(late, shapes, handover=closes + 2)  # after its verdict: none more
    assert verdict.fillet_id == 1 and verdict.scored and late.taken_over == 1


def test_a_fillet_whose_track_went_on_with_its_lane_mate_gets_one_verdict_from_the_track_that_found_it_again():
    """Crowded lane: track 1 follows a fillet flat and track 3 its lane-mate ahead; as the lane-mate reaches the
    edge, track 1 takes its blob (track 3 no longer sees it) and the fillet, still flat, opens track 2. Track 2
    carries the fillet's evaluation and track 1 the lane-mate's: one verdict each, the ones they get alone."""
    shapes = contours(120, start_tip_v=20.0, bend=0.4)
    ((_, plain),) = feed(FilletGrader(EDGE, GradingRules(threshold=1.0)), 1, 0, shapes, end=True)
    ahead = contours(120, start_tip_v=140.0, bend=0.4)  # the lane-mate, just over a fillet length ahead
    switch = next(i for i, c in enumerate(ahead) if c[:, 1].max() >= EDGE + 10)  # the fillet itself is flat there
    assert shapes[switch][:, 1].max() < EDGE - 50
    grader, out = FilletGrader(EDGE, GradingRules(threshold=1.0)), []
    for i, (contour, mate) in enumerate(zip(shapes, ahead)):
        if i < switch:
            observed = [TrackObservation(1, 0, contour), TrackObservation(3, 0, mate)]
        else:
            observed = [TrackObservation(1, 0, mate), TrackObservation(2, 0, contour),
                        TrackObservation(3, 0, ahead[switch - 1], unseen=i - switch + 1)]
        out += grader.on_tracks(i / FPS, observed)
    out += grader.on_tracks(len(shapes) / FPS, [], ended_ids=[1, 2, 3])
    fillet, lane_mate = (v for v in out if v.fillet_id == 2), (v for v in out if v.fillet_id == 1)
    assert len(out) == 2 and grader.taken_over == 2
    for (verdict,) in (fillet, lane_mate):
        assert verdict.scored and verdict.shape.line_phi == pytest.approx(plain.shape.line_phi)


def beside_a_neighbour(grader: FilletGrader, shapes, lost: frozenset[int] = frozenset()) -> GradedFillet:
    """Track 1's verdict when track 2's outline, a band beside its footprint (never inside it, as no two fillets'
    footprints overlap), lies against its right side over the 30 rows before the edge in every frame but the
    ``lost`` ones (no frame came)."""
    out = []
    for i, contour in enumerate(shapes):
        if i in lost:
            continue
        side = contour[(contour[:, 0] > 300) & (contour[:, 1] >= EDGE - 30) & (contour[:, 1] <= EDGE)]
        side = side[np.argsort(side[:, 1], kind="stable")] + np.array([2, 0], np.int32)
        neighbour = np.concatenate([side, side[::-1] + np.array([40, 0], np.int32)])
        observed = [TrackObservation(1, 0, contour)] + ([TrackObservation(2, 1, neighbour)] if len(neighbour) else [])
        out += grader.on_tracks(i / FPS, observed)
    (verdict,) = [v for v in out if v.fillet_id == 1]
    return verdict


def test_a_fillet_graded_normal_on_frames_split_from_a_neighbour_near_the_cut_is_unscored():
    shapes = contours(90, bend=0.4)
    ((_, alone),) = feed(FilletGrader(EDGE, GradingRules(threshold=1.0)), 1, 0, shapes)
    near = alone.score / math.exp(0.5 * JOINED_MARGIN_LN)  # the score lies just above this cut
    verdict = beside_a_neighbour(FilletGrader(EDGE, GradingRules(threshold=near)), shapes)
    assert verdict.label == "unscored" and verdict.reason.startswith("outline split from a neighbour's")
    assert feed(FilletGrader(EDGE, GradingRules(threshold=near)), 1, 0, shapes)[0][1].label == "normal"
    far = alone.score / math.exp(2.0 * JOINED_MARGIN_LN)
    assert beside_a_neighbour(FilletGrader(EDGE, GradingRules(threshold=far)), shapes).label == "normal"


def widened(contour: np.ndarray, factor: float = 1.5) -> np.ndarray:
    """The outline a fillet merged with its side neighbour gives: too wide to be the fillet alone."""
    out = contour.copy()
    out[:, 0] = np.round(300 + (out[:, 0] - 300) * factor)
    return out


def test_a_fillet_graded_normal_on_frames_split_from_a_neighbour_after_a_merged_window_is_unscored():
    shapes = contours(90, bend=0.4)
    ((_, alone),) = feed(FilletGrader(EDGE, GradingRules(threshold=1.0)), 1, 0, shapes)
    far = alone.score / math.exp(2.0 * JOINED_MARGIN_LN)  # far below the score: no margin rule applies
    opens = round(alone.shape.trace[0].stamp * FPS)
    for merged, label in ((JOINED_MERGED_FRAMES - 1, "normal"), (JOINED_MERGED_FRAMES, "unscored")):
        frames = [widened(c) if opens <= i < opens + merged else c for i, c in enumerate(shapes)]
        verdict = beside_a_neighbour(FilletGrader(EDGE, GradingRules(threshold=far)), frames)
        assert verdict.shape.rejected_frames == merged and verdict.label == label
    assert verdict.reason.startswith(f"outline joined a neighbour's through its window ({merged} frames merged, "
                                     "0.000 s of frames lost)")
    assert feed(FilletGrader(EDGE, GradingRules(threshold=far)), 1, 0, frames)[0][1].label == "normal"  # not joined


def test_a_fillet_graded_normal_on_frames_split_from_a_neighbour_in_a_window_with_frames_lost_is_unscored():
    shapes = contours(90, bend=0.4)
    ((_, alone),) = feed(FilletGrader(EDGE, GradingRules(threshold=1.0)), 1, 0, shapes)
    far = alone.score / math.exp(2.0 * JOINED_MARGIN_LN)  # far below the score: no margin rule applies
    opens = round(alone.shape.trace[0].stamp * FPS)
    lost = frozenset({opens + 1, opens + 2})
    verdict = beside_a_neighbour(FilletGrader(EDGE, GradingRules(threshold=far)), shapes, lost)
    assert verdict.label == "unscored" and verdict.shape.window_gap_s == pytest.approx(3 / FPS)
    assert verdict.reason.startswith("outline joined a neighbour's through its window (0 frames merged, 0.100 s")
    assert beside_a_neighbour(FilletGrader(EDGE, GradingRules(threshold=far)), shapes).label == "normal"


def merged_around_the_point(shapes, threshold: float, before: int = 4, past: int | None = 2) -> GradedFillet:
    """The verdict of a fillet merged with its side neighbour from ``before`` frames before the first frame past its
    measuring point to ``past`` frames after that one (to its last frame with None): too far apart for the frames
    left to read the point."""
    ((_, alone),) = feed(FilletGrader(EDGE, GradingRules(threshold=1.0)), 1, 0, shapes)
    frames = alone.shape.trace + alone.shape.extra_trace
    point = round(next(f for f in frames if f.overhang >= alone.shape.line_fraction).stamp * FPS)
    last = len(shapes) if past is None else point + past
    merged = [widened(c) if point - before <= i < last else c for i, c in enumerate(shapes)]
    ((_, verdict),) = feed(FilletGrader(EDGE, GradingRules(threshold=threshold)), 1, 0, merged)
    return verdict


def test_a_fillet_merged_around_its_measuring_point_is_graded_when_the_frames_around_it_bound_its_score():
    shapes = contours(90, bend=0.4)
    gap = merged_around_the_point(shapes, threshold=1.0)
    low, high = gap.shape.line_bounds
    assert 0.0 < low < high < math.inf
    for threshold, label, score in ((1.01 * high, "woody", high), (0.99 * low, "normal", low)):
        verdict = merged_around_the_point(shapes, threshold)
        assert verdict.label == label and verdict.scored and verdict.score == score
        assert verdict.reason == REASON_BOUND.format(low, high)
    between = merged_around_the_point(shapes, threshold=0.5 * (low + high))
    assert between.label == "unscored" and between.reason.startswith("no clean frames around the measuring point")


def test_a_fillet_merged_from_before_its_measuring_point_on_is_unscored_whatever_its_score_before_it():
    """Blunt end first, the window closes before the measuring point: every frame from the close on merged, nothing
    bounds the score from above."""
    shapes = contours(90, bend=0.4, narrow_first=False)
    ((_, alone),) = feed(FilletGrader(EDGE, GradingRules(threshold=1.0)), 1, 0, shapes)
    verdict = merged_around_the_point(shapes, threshold=0.01 * alone.score, before=1, past=None)
    low, high = verdict.shape.line_bounds
    assert 0.01 * alone.score < low and high == math.inf
    assert verdict.label == "unscored" and verdict.reason.startswith("no clean frames around the measuring point")


def test_a_sliver_lost_on_the_belt_beside_its_lane_fillet_gets_no_verdict_but_a_lost_fillet_does():
    """A crowded lane's split can leave a sliver that lives a few frames on the belt: the fillet it came off gets
    the verdict, the sliver none; a lost fillet of a fillet's size still gets its unscored verdict."""
    grader = FilletGrader(EDGE, GradingRules(threshold=1.0))
    shapes = contours(90)
    sliver = np.array([[290, 60], [310, 60], [310, 80], [290, 80]], np.int32)
    other = contours(1, start_tip_v=60.0)[0]  # a whole fillet's outline behind it
    for i, contour in enumerate(shapes[:5]):
        observed = [TrackObservation(1, 0, contour), TrackObservation(2, 0, sliver), TrackObservation(3, 0, other)]
        assert grader.on_tracks(i / FPS, observed) == []
    (lost,) = grader.on_tracks(5 / FPS, [TrackObservation(1, 0, shapes[5])], ended_ids=[2, 3])
    assert lost.fillet_id == 3 and lost.label == "unscored" and lost.shape.reason == REASON_LOST_BEFORE_EDGE
    assert grader.fragments == 1


def test_a_track_seen_only_twice_then_lost_gives_no_verdict():
    grader = FilletGrader(EDGE)
    assert feed(grader, 4, 0, contours(2), end=True) == [] and grader.tentative == 1
    ((_, lost),) = feed(grader, 5, 0, contours(3), end=True)  # three sightings: an unscored verdict
    assert lost.label == "unscored"


def test_unseen_observations_do_not_feed_the_evaluator():
    grader = FilletGrader(EDGE)
    shapes = contours(90)
    past_edge = contours(1, start_tip_v=EDGE + 40.0)[0]
    assert grader.on_tracks(0.0, [TrackObservation(4, 0, shapes[0])]) == []
    assert grader.on_tracks(0.03, [TrackObservation(4, 0, past_edge, unseen=1)]) == []
    out = feed(grader, 4, 0, shapes[1:], t0=0.07)
    ((_, verdict),) = out
    assert verdict.scored and verdict.shape.phi < 1e-6


def watched_verdict(grader: FilletGrader, track_id: int, shapes, t0: float = 0.0) -> GradedFillet:
    """Feed a watched-lane track through its window's close: its verdict comes out at the close, never held."""
    ((stamp, verdict),) = [(s, v) for s, v in feed(grader, track_id, WATCHED, through_close(shapes), t0)]
    assert crossed_just_before(stamp, verdict) and verdict.shape.stamp == pytest.approx(closing_stamp(shapes, t0))
    return verdict


def test_watched_lane_verdict_goes_out_at_once_and_its_side_result_when_the_passage_ends():
    grader = FilletGrader(EDGE, watched_lane=WATCHED, side_wait_s=WAIT)
    shapes = contours(120)
    verdict = watched_verdict(grader, 5, shapes)
    close = verdict.shape.stamp
    assert grader.release(close + 0.5 * WAIT) == [], "the side result waits for the side passage"
    (result,) = grader.on_side(side(close - 0.1, close + 0.3, nmdm=0.42))
    assert result == SideResult(5, WATCHED, close, result.side, "") and result.side.nmdm == 0.42
    # one side result per fillet: none when the wait runs out, no verdict when the track ends
    assert grader.release(close + 10 * WAIT) == []
    assert grader.on_tracks(close + 11 * WAIT, [], ended_ids=[5]) == []


def test_side_result_after_side_wait_without_a_measurement_says_why():
    grader = FilletGrader(EDGE, watched_lane=WATCHED, side_wait_s=WAIT)
    close = watched_verdict(grader, 6, contours(90)).shape.stamp
    assert grader.side_seen(close + WAIT - 0.01) == []
    (result,) = grader.side_seen(close + WAIT)
    assert result.fillet_id == 6 and result.side is None and result.reason == REASON_NO_SIDE.format(WAIT)
    assert grader.side_seen(close + 2 * WAIT) == [] and grader.release(close + 10 * WAIT) == []


def test_a_grader_behind_on_its_side_frames_waits_for_them():
    """The top camera's clock past the side wait says nothing of side frames still queued: their passage counts."""
    grader = FilletGrader(EDGE, watched_lane=WATCHED, side_wait_s=WAIT)
    close = watched_verdict(grader, 13, contours(90)).shape.stamp
    assert grader.release(close + WAIT + SIDE_SILENT_S - 0.01) == []
    (result,) = grader.on_side(side(close - 0.1, close + 0.3, nmdm=0.42))
    assert result.fillet_id == 13 and result.side.nmdm == 0.42 and result.reason == ""


def test_a_silent_side_camera_ends_the_wait_on_the_top_cameras_clock():
    grader = FilletGrader(EDGE, watched_lane=WATCHED, side_wait_s=WAIT)
    close = watched_verdict(grader, 14, contours(90)).shape.stamp
    grader.side_seen(close - 1.0)  # its last frame came before the window closed
    assert grader.release(close + WAIT + SIDE_SILENT_S - 0.01) == []
    (result,) = grader.release(close + WAIT + SIDE_SILENT_S)
    assert result.fillet_id == 14 and result.side is None and result.reason == REASON_NO_SIDE.format(WAIT)


def test_side_measurement_that_arrived_first_is_paired_at_the_next_release():
    grader = FilletGrader(EDGE, watched_lane=WATCHED, side_wait_s=WAIT)
    shapes = contours(90)
    close = closing_stamp(shapes)
    assert grader.on_side(side(close - 0.4, close - 0.1)) == []  # within the slack before the closing frame
    watched_verdict(grader, 9, shapes)
    (result,) = grader.release(close)
    assert result.fillet_id == 9 and result.side is not None


def test_side_measurement_of_another_time_is_not_attached():
    grader = FilletGrader(EDGE, watched_lane=WATCHED, side_wait_s=WAIT)
    t0 = 5.0
    close = watched_verdict(grader, 10, contours(90), t0=t0).shape.stamp
    assert grader.on_side(side(close - 3.0, close - 2.0)) == []
    assert grader.on_side(side(close + SIDE_MATCH_SLACK_S + 0.05, close + 0.6)) == []
    (result,) = grader.side_seen(close + WAIT)
    assert result.side is None


def test_two_watched_fillets_each_get_their_own_side_measurement():
    grader = FilletGrader(EDGE, watched_lane=WATCHED, side_wait_s=WAIT)
    shapes = contours(90)
    close_a = watched_verdict(grader, 11, shapes, t0=0.0).shape.stamp
    close_b = closing_stamp(shapes, 1.0)
    later = side(close_b - 0.1, close_b + 0.2, nmdm=0.8)
    assert grader.on_side(later) == [], "B's passage does not overlap A's window"
    (a,) = grader.on_side(side(close_a - 0.1, close_a + 0.2, nmdm=0.4))
    assert a.fillet_id == 11 and a.side.nmdm == 0.4
    watched_verdict(grader, 12, shapes, t0=1.0)
    (b,) = grader.release(close_b)
    assert b.fillet_id == 12 and b.side is later


def test_other_lanes_and_no_watched_lane_have_no_side_results():
    for watched in (None, WATCHED):
        grader = FilletGrader(EDGE, watched_lane=watched)
        lane = 0 if watched is not None else WATCHED
        ((stamp, verdict),) = feed(grader, 13, lane, contours(90))
        assert crossed_just_before(stamp, verdict) and verdict.reason == ""
        assert grader.release(1e9) == [] and grader.on_side(side(stamp - 0.1, stamp + 0.2)) == []


def test_many_tracks_in_one_frame_each_get_one_verdict():
    grader = FilletGrader(EDGE, watched_lane=None)
    shapes = contours(90)
    verdicts = []
    for i, contour in enumerate(shapes):
        tracks = [TrackObservation(tid, tid % 3, contour + np.array([120 * tid, 0], np.int32)) for tid in range(5)]
        verdicts += grader.on_tracks(i / FPS, tracks)
    verdicts += grader.on_tracks(len(shapes) / FPS, [], ended_ids=range(5))
    assert sorted(v.fillet_id for v in verdicts) == [0, 1, 2, 3, 4]
    assert [v.lane for v in sorted(verdicts, key=lambda v: v.fillet_id)] == [0, 1, 2, 0, 1]


def test_grader_validates_its_options():
    with pytest.raises(ValueError):
        FilletGrader(EDGE, side_wait_s=-0.1)
    with pytest.raises(ValueError):
        FilletGrader(EDGE, evaluator_options={"tip_ratio": 2.0})
    assert math.isinf(FilletGrader(EDGE).now)


def test_a_side_passage_with_lost_frames_gives_no_side_metrics_but_the_reason():
    grader = FilletGrader(EDGE, watched_lane=WATCHED, side_wait_s=WAIT)
    verdict = watched_verdict(grader, 14, contours(90))
    close = verdict.shape.stamp
    assert verdict.scored and verdict.reason == ""
    nan = math.nan
    partial = SideMeasurement(nmdm=nan, mdm_min_px=nan, be=nan, h_px=nan, stamp_of_min=nan, first_stamp=close - 0.1,
                              last_stamp=close + 0.3, frames=12, reason="side view absent: frames lost in the passage")
    (result,) = grader.on_side(partial)
    assert result.side is partial and math.isnan(result.side.nmdm)
    assert result.reason == "side view absent: frames lost in the passage"


def test_a_window_with_lost_frames_is_unscored_on_the_paper_score_and_has_no_phi_on_the_line_score():
    shapes = contours(90, bend=0.5)
    ((_, whole),) = feed(FilletGrader(EDGE, GradingRules(5.0)), 0, 0, shapes)
    opens = round(whole.shape.trace[0].stamp * FPS)
    kept = shapes[:opens + 1] + shapes[opens + 3:]  # two frames lost in the window
    stamps = [i / FPS for i in range(len(shapes)) if not opens + 1 <= i <= opens + 2]
    for score in ("paper", "line"):
        grader = FilletGrader(EDGE, GradingRules(5.0), score=score)
        (verdict,) = [v for stamp, contour in zip(stamps, kept)
                      for v in grader.on_tracks(stamp, [TrackObservation(0, 0, contour)])]
        assert math.isnan(verdict.shape.phi) and verdict.reason.startswith("phi absent: frames lost")
        if score == "paper":
            assert verdict.label == "unscored"
        else:  # the line score is measured at its own moment, between frames that did arrive
            assert (verdict.label, verdict.score) == (whole.label, whole.score) and whole.label != "unscored"


def test_after_a_reset_the_same_frames_give_the_same_verdicts():
    """Sim time went back (a replay started again): the grader forgets what was in progress and grades anew."""
    grader = FilletGrader(EDGE, watched_lane=WATCHED, side_wait_s=WAIT)
    shapes = contours(90)
    runs = []
    for _ in range(2):
        verdict = watched_verdict(grader, 17, shapes, t0=5.0)
        close = verdict.shape.stamp
        runs.append((verdict, grader.on_side(side(close - 0.1, close + 0.3, nmdm=0.42))))
        watched_verdict(grader, 18, shapes, t0=20.0)  # waiting for its side passage when time goes back
        assert grader.reset() == (2, 1)  # tracks 17 (not ended yet) and 18, and 18's side result to come
        assert math.isinf(grader.now) and grader.reset() == (0, 0)
    (first, (first_side,)), (second, (second_side,)) = runs
    assert first_side.side.nmdm == second_side.side.nmdm == 0.42
    assert first.shape.phi == second.shape.phi and first.label == second.label
