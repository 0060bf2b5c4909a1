"""One verdict per fillet from the top-down shape score; for the watched lane, its side-view metrics apart.

Plain module (no rclpy): the grader node feeds it tracks and side frames; the
experiment runner and the benchmark feed it the same way without ROS.

The top-down window of a fillet closes when its virtual centroid crosses the
roller edge, and its verdict goes out then: the gate downstream needs it in
time. The side camera finishes measuring that fillet a little later (it is
still falling), so the watched lane's side metrics are a result of their own
(:class:`SideResult`), paired with the verdict by fillet id once the side
passage that overlaps it ends, or after ``side_wait_s`` of the side camera's
time without one (:meth:`FilletGrader.side_seen`): a grader behind on its
queued side frames never calls absent a passage it has yet to read. A side
result without a whole side passage has NMDM, MDM and BE absent
and says why, like one whose passage lost frames (woody_vision.side_view); Φ
over a window with lost frames is absent the same way
(woody_vision.shape_score). When sim time goes back (a replay started again)
the node calls :meth:`FilletGrader.reset`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from woody_common.calibration import resolved_calibration
from woody_vision.grading import LABEL_NORMAL, LABEL_UNSCORED, FilletConditions, FittedRange, GradingRules
from woody_vision.shape_score import (
    LEADING_BLUNT,
    MIN_SIGHTINGS,
    REASON_LOST_BEFORE_EDGE,
    REASON_OVERDUE_BEFORE_EDGE,
    REASON_STARTED_PAST_EDGE,
    STATUS_SCORED,
    STATUS_UNSCORED,
    ShapeEvaluator,
    ShapeResult,
)
from woody_vision.side_view import SideMeasurement

DEFAULT_SIDE_WAIT_S = 0.8
"""Longest a watched-lane fillet's side result waits for its side passage to end (sim s)."""

SIDE_SILENT_S = 2.0
"""A side camera that sent nothing this long (sim s) past a fillet's side wait is taken as gone: its side result goes
out absent by the top camera's clock instead (a line without a side camera, a bag replayed without its frames)."""

REASON_NO_SIDE = "side view absent: no whole side passage of this fillet ended within {:.1f} s of its window"

REASON_BOUND = ("line score read as a bound: frames lost or merged around the measuring point, where Φ_t lies "
                "between {:.2f} and {:.2f}")

SIDE_MATCH_SLACK_S = 0.3
"""A side passage matches a top-down window closing up to this long before or after the passage."""


def calibrated_rules(calibration) -> GradingRules:
    """The line's rules from a calibration: the reject cut and the grade's severe cut on ``line_phi``."""
    return GradingRules(calibration.line_threshold, calibration.severe_threshold)


def calibrated_range(calibration) -> FittedRange:
    """The measured conditions a calibration's cuts were fitted on."""
    return FittedRange.of(calibration.fitted_range)


@dataclass(frozen=True)
class TrackObservation:
    """One track of one top-down frame, as the segmenter publishes it."""

    track_id: int
    lane: int
    contour: np.ndarray
    """The outline the grade follows (on a line: the belt outline, woody_vision.camera_model.belt_outline)."""
    unseen: int = 0
    image_contour: np.ndarray | None = None
    """The outline in the image, for the paper's Φ (None: ``contour``)."""


@dataclass(frozen=True)
class GradedFillet:
    """Everything a verdict message carries."""

    fillet_id: int
    lane: int
    shape: ShapeResult
    label: str
    """'normal', 'woody' or 'unscored'."""
    grade: str
    """'normal' / 'moderate' / 'severe' when grading, else ''."""
    score: float = math.nan
    """The score the decision used (``line_phi`` or the paper's Φ, see :class:`FilletGrader`)."""
    conditions: FilletConditions | None = None
    """What the top camera measured of the fillet's speed and direction."""
    threshold: float = math.nan
    """The reject cut's value for this fillet."""

    @property
    def scored(self) -> bool:
        return self.shape.status == STATUS_SCORED

    @property
    def reason(self) -> str:
        """Why the fillet is unscored or a metric is absent ('' when every metric it should carry is there)."""
        return self.shape.reason


@dataclass(frozen=True)
class SideResult:
    """The side view's measurement of one watched-lane fillet, paired with its verdict by fillet id."""

    fillet_id: int
    lane: int
    stamp: float
    """The stamp of the fillet's verdict (its window's close)."""
    side: SideMeasurement | None
    """None when no side passage of the fillet ended within ``side_wait_s``."""
    reason: str
    """Why a metric is absent ('' when NMDM, MDM and BE are all measured)."""


SCORE_LINE = "line"
SCORE_PAPER = "paper"
SCORES = (SCORE_LINE, SCORE_PAPER)


def check_score(score: str) -> str:
    """``score`` if it names a score the grader can grade on; a ValueError otherwise."""
    if score not in SCORES:
        raise ValueError(f"score must be one of {', '.join(SCORES)}, got {score!r}")
    return score

PIECE_AREA_RATIO = 0.5
"""A track first seen past the edge is a split-off piece of its lane's fillet when its blob is smaller than this
fraction of that fillet's flat outline (:meth:`FilletGrader._is_piece`)."""

PIECE_REASONS = (REASON_STARTED_PAST_EDGE, REASON_LOST_BEFORE_EDGE, REASON_OVERDUE_BEFORE_EDGE)
"""The unscored results :meth:`FilletGrader._is_piece` checks: a track only a piece of a fillet ends so."""

JOINED_MARGIN_LN = 0.2
"""A fillet graded normal on a line score read on frames split from a neighbour's outline
(``ShapeResult.joined_at_line``) with its score less than this above the cut (in ln) is unscored, so the gate
diverts it: a split that gave the fillet a piece of its neighbour raises its score by about that much or more in
one such fillet in ten. Chosen on one set of live runs and checked on a disjoint one (docs/results.md)."""

REASON_JOINED = ("outline split from a neighbour's at the measuring point, score {:.2f} within {:.0%} of the cut "
                 "{:.2f}")

JOINED_MERGED_FRAMES = 3
"""A fillet graded normal on frames split from a neighbour's outline at the measuring point, in a window where at
least this many frames (0.1 s at 30 Hz) were rejected as merged with a neighbour, or where frames of it were lost
(its track saw only the joined blob's other part), is unscored whatever its score: it lay joined to the neighbour
through much of its window, and the split hands pieces of the outline to one or the other, so its score says
little. Chosen on one set of live runs and checked on disjoint ones (docs/results.md)."""

REASON_JOINED_THROUGH = ("outline joined a neighbour's through its window ({} frames merged, {:.3f} s of frames lost) "
                         "and split from it at the measuring point")


@dataclass(frozen=True)
class _Pending:
    fillet_id: int
    lane: int
    stamp: float
    deadline: float


@dataclass
class FilletGrader:
    """Per-track shape evaluation and classification; side-view pairing for the watched lane."""

    edge_row: float
    rules: GradingRules = field(default_factory=lambda: calibrated_rules(resolved_calibration()))
    """Default: the line cuts of the resolved calibration (woody_common.calibration.resolve_calibration); the
    grader node and the experiment runs always pass theirs."""
    watched_lane: int | None = None
    side_wait_s: float = DEFAULT_SIDE_WAIT_S
    evaluator_options: dict = field(default_factory=dict)
    pixels_per_metre: float = math.nan
    """Top camera pixels per metre on the belt plane (focal length / height): turns image speed into m/s."""
    score: str = SCORE_LINE
    """'line': grade ``line_phi`` (the default, robust to speed, direction and turn); 'paper': the paper's Φ."""
    fitted_range: FittedRange | None = field(default_factory=lambda: calibrated_range(resolved_calibration()))
    """A fillet measured outside it is unscored (fail safe); None grades every fillet (a user's explicit choice)."""

    def __post_init__(self) -> None:
        check_score(self.score)
        if self.side_wait_s < 0:
            raise ValueError(f"side_wait_s must be >= 0, got {self.side_wait_s}")
        ShapeEvaluator(self.edge_row, **self.evaluator_options)  # validate options now
        self._forget()
        self.fragments = 0
        """Tracks dropped as split-off pieces of a fillet already being graded (see :meth:`_is_piece`), or as what a
        track that lost its fillet to another followed past the edge (see :meth:`_adopted`)."""
        self.taken_over = 0
        """Tracks that started where a lane-mate's fillet, lost by its own track, should be, and carried on its
        evaluation (see :meth:`_adopted`)."""
        self.tentative = 0
        """Tracks that ended after fewer than MIN_SIGHTINGS frames (a fillet's first sightings at the image border
        before a burst of lost frames, noise): no verdict, like a tentative track in SORT-style trackers."""

    @property
    def in_progress(self) -> int:
        """Fillets being scored now: each one's verdict is still to come."""
        return len(self._evaluators)

    def reset(self) -> tuple[int, int]:
        """Forget every fillet (evaluators, fillets waiting for their side result, side measurements) and the
        time: sim time went back, and what was in progress belongs to a timeline that is gone. Returns (tracks,
        side results) dropped."""
        dropped = (len(self._evaluators), len(self._pending))
        self._forget()
        return dropped

    def _forget(self) -> None:
        self._evaluators: dict[int, ShapeEvaluator] = {}
        self._lanes: dict[int, int] = {}
        self._bereft: set[int] = set()
        """Tracks whose fillet's evaluation another track carries on (:meth:`_adopted`)."""
        self._pending: list[_Pending] = []
        self._side: list[SideMeasurement] = []
        self.now = -math.inf
        self.side_now = -math.inf
        """The stamp of the newest side frame the side view has read."""

    def on_tracks(self, stamp: float, tracks: Sequence[TrackObservation],
                  ended_ids: Iterable[int] = ()) -> list[GradedFillet]:
        """Feed one top-down frame; returns the verdicts decided now (side results come from :meth:`release`)."""
        self.now = max(self.now, stamp)
        decided: list[GradedFillet] = []
        outlines = {track.track_id: _outline(track.contour) for track in tracks if not track.unseen}
        for track in sorted(tracks, key=lambda t: t.track_id not in self._evaluators):  # new tracks last
            self._lanes[track.track_id] = track.lane
            if track.unseen:
                continue
            evaluator = self._evaluators.get(track.track_id)
            if evaluator is None:
                evaluator = self._evaluators[track.track_id] = (self._adopted(track, stamp) or ShapeEvaluator(
                    self.edge_row, **self.evaluator_options))
            neighbours = [outline for other, outline in outlines.items() if other != track.track_id]
            result = evaluator.update(track.contour, stamp, track.image_contour, neighbours)
            if result is not None:  # a finished evaluator stays until its track ends: one verdict per track
                decided += self._decide(track.track_id, result, _area(track.contour))
        for track in tracks:
            evaluator = self._evaluators.get(track.track_id)
            if evaluator is not None:
                decided += self._conclude(track.track_id, evaluator, evaluator.overdue(stamp))
        for track_id in ended_ids:
            evaluator = self._evaluators.pop(track_id, None)
            if evaluator is not None:
                decided += self._conclude(track_id, evaluator, evaluator.finish())
            self._lanes.pop(track_id, None)
            self._bereft.discard(track_id)
        return decided

    def _conclude(self, track_id: int, evaluator: ShapeEvaluator, result: ShapeResult | None) -> list[GradedFillet]:
        """The verdict of a track that ended or whose fillet is overdue at the edge (``result``; None: no verdict
        now). A track seen only once or twice gives none: the grader cannot stand behind it."""
        if result is None:
            return []
        if evaluator.sightings < MIN_SIGHTINGS:
            self.tentative += 1
            return []
        return self._decide(track_id, result, evaluator.flat_area)

    def frame_phi(self, track_id: int, stamp: float) -> float:
        """Φ_t of the track's frame at ``stamp`` (NaN when that frame was not scored): the overlays' label."""
        evaluator = self._evaluators.get(track_id)
        frame = evaluator.last_frame if evaluator is not None else None
        return frame.phi if frame is not None and frame.stamp == stamp else math.nan

    def on_side(self, measurement: SideMeasurement) -> list[SideResult]:
        """Pair a finished side-view passage with the fillet it overlaps; returns the side results now known."""
        self._side.append(measurement)
        self._side = [m for m in self._side if m.last_stamp >= self.now - 5.0]
        return self.release(self.now)

    def side_seen(self, stamp: float) -> list[SideResult]:
        """The side view has read every side frame up to ``stamp``: the side results now known."""
        self.side_now = max(self.side_now, stamp)
        return self.release(self.now)

    def release(self, now: float) -> list[SideResult]:
        """Side results of the watched-lane fillets whose passage ended or that waited long enough (``side_wait_s``
        on the side camera's clock, or SIDE_SILENT_S more on the top camera's ``now``)."""
        self.now = max(self.now, now)
        out: list[SideResult] = []
        keep: list[_Pending] = []
        for pending in self._pending:
            side = self._match_side(pending.stamp)
            if side is not None:
                out.append(SideResult(pending.fillet_id, pending.lane, pending.stamp, side, side.reason))
            elif self.side_now >= pending.deadline or self.now >= pending.deadline + SIDE_SILENT_S:
                out.append(SideResult(pending.fillet_id, pending.lane, pending.stamp, None,
                                      REASON_NO_SIDE.format(self.side_wait_s)))
            else:
                keep.append(pending)
        self._pending = keep
        return out

    def _decide(self, track_id: int, result: ShapeResult, area_px: float = 0.0) -> list[GradedFillet]:
        lane = self._lanes.get(track_id, -1)
        bereft = track_id in self._bereft and result.reason == REASON_STARTED_PAST_EDGE
        graded = self._classify(track_id, lane, result)
        if bereft or self._is_fragment(lane, track_id, result, graded, area_px):
            self.fragments += 1
            return []
        if self.watched_lane is not None and lane == self.watched_lane:
            stamp = self.now if result.stamp is None else result.stamp
            self._pending.append(_Pending(track_id, lane, stamp, deadline=stamp + self.side_wait_s))
        return [graded]

    def _classify(self, track_id: int, lane: int, result: ShapeResult) -> GradedFillet:
        """The verdict of a finished window: scored and classified, or unscored with its reason."""
        paper = self.score == SCORE_PAPER
        conditions = FilletConditions(result.speed_px_s / self.pixels_per_metre, result.leading_end == LEADING_BLUNT,
                                      result.turn_deg, result.length_px / self.pixels_per_metre)
        result = result if paper else self._bounded(result, conditions)
        score = result.phi if paper else result.line_phi
        usable = result.window_closed if paper else result.status == STATUS_SCORED
        if not (usable and math.isfinite(score)):
            return GradedFillet(track_id, lane, result, LABEL_UNSCORED, "", conditions=conditions)
        outside = self.fitted_range.outside(conditions) if self.fitted_range is not None else ""
        if outside:
            result = replace(result, status=STATUS_UNSCORED, reason="; ".join(r for r in (outside, result.reason) if r))
            return GradedFillet(track_id, lane, result, LABEL_UNSCORED, "", conditions=conditions)
        decision = self.rules.classify(score, conditions)
        doubt = _joined_doubt(result, score, decision.threshold) if decision.label == LABEL_NORMAL and not paper else ""
        if doubt:
            result = replace(result, status=STATUS_UNSCORED, reason="; ".join(r for r in (doubt, result.reason) if r))
            return GradedFillet(track_id, lane, result, LABEL_UNSCORED, "", conditions=conditions)
        return GradedFillet(track_id, lane, result, decision.label, decision.grade or "", score=score,
                            conditions=conditions, threshold=decision.threshold)

    def _bounded(self, result: ShapeResult, conditions: FilletConditions) -> ShapeResult:
        """``result`` scored on a bound of its line score when no two frames read the measuring point but the
        bounds alone decide (``ShapeResult.line_bounds``): a fillet whose Φ_t is below the cut on its first own
        frame past the point is woody, and that score, at least its line score, is the one graded; one whose Φ_t
        is above it on its last own frame before the point, and on a later own frame that confirms it, is normal.
        Unchanged otherwise."""
        low, high = result.line_bounds
        if result.status == STATUS_SCORED or not math.isfinite(high):
            return result
        woody_high = self.rules.is_woody(high, conditions)
        if woody_high or (low > 0.0 and not self.rules.is_woody(low, conditions)):
            return replace(result, status=STATUS_SCORED, line_phi=high if woody_high else low,
                           reason=REASON_BOUND.format(low, high))
        return result

    def _adopted(self, track: TrackObservation, stamp: float) -> ShapeEvaluator | None:
        """The evaluation a new track carries on: that of a fillet of its lane whose own track lost it in this
        frame (the frame was rejected, or the track not seen; the known tracks are fed first) and whose trailing
        edge should lie where the new track's does (TRAILING_LEAP_RATIO), so the fillet gets its one verdict
        (none more if it already had it). Its track lost it as it tipped (it took a piece split off at the edge,
        or went unseen), or, in a crowded lane, went on with the blob of the lane-mate hanging ahead after the
        two merged; the fillet's outline then opens a new track, past the edge or before it. The track that
        lost it gives no verdict for what it follows past the edge without a reference (:meth:`_decide`): a
        piece, or its lane-mate, whose evaluation it carries on by this same rule when that one's track lost
        it."""
        trailing = float(_outline(track.contour)[:, 1].min())
        owner = next((other for other, evaluator in self._evaluators.items()
                      if other != track.track_id and self._lanes.get(other) == track.lane
                      and evaluator.lost_at(stamp) and evaluator.continues_at(trailing, stamp)), None)
        if owner is None:
            return None
        self.taken_over += 1
        self._bereft.add(owner)
        return self._evaluators.pop(owner)

    def _is_fragment(self, lane: int, track_id: int, result: ShapeResult, graded: GradedFillet,
                     area_px: float) -> bool:
        """Whether a result is a piece's (:meth:`_is_piece`): a track that ended as only a piece's does
        (PIECE_REASONS), with the blob's ``area_px``, or any window whose flat reference outline was a piece's, with
        that outline's area, that its evaluator left unscored or its verdict (``graded``) is (a split of two
        touching fillets gave a sliver a track of its own before the edge; it opens a window it cannot score, or
        scores one outside the calibration: shorter, or turned further, than any fillet). A piece's window read
        as a bound is still a piece's."""
        if result.reason in PIECE_REASONS:
            return self._is_piece(lane, track_id, area_px)
        unscored = result.status == STATUS_UNSCORED or not graded.scored
        piece_window = unscored and result.reference_contour is not None
        return piece_window and self._is_piece(lane, track_id, _area(result.reference_contour))

    def _is_piece(self, lane: int, track_id: int, area_px: float) -> bool:
        """Whether a track that first appears past the edge, or ends before its body reaches it, is a piece of a
        fillet of its lane being graded.

        A noisy camera's tip going over the edge splits off a small piece next
        to a fillet of the same lane that was seen flat before the edge, and a
        crowded lane's split of two touching fillets can leave a sliver that
        lives a few frames on the belt: neither gets a verdict, so the gate and
        the sweep hear only the whole fillet's. A blob of at least
        PIECE_AREA_RATIO of that fillet's flat area is a fillet of its own (hidden
        in a neighbour's blob until the edge, or lost on the belt): it gets its
        unscored verdict, so the gate diverts it. That flat area counts up to the
        median of the fillets being graded: on a line with 2 cm gaps a lane-mate's
        flat outline can be two touching fillets' joined blob, beside which a
        whole fillet would pass for a piece and get no verdict.
        """
        others = {other: evaluator for other, evaluator in self._evaluators.items() if other != track_id}
        areas = [evaluator.flat_area for evaluator in others.values() if math.isfinite(evaluator.flat_area)]
        typical = float(np.median(areas)) if areas else math.inf
        return any(self._lanes.get(other) == lane and area_px < PIECE_AREA_RATIO * min(evaluator.flat_area, typical)
                   for other, evaluator in others.items())

    def _match_side(self, closing: float) -> SideMeasurement | None:
        for i, m in enumerate(self._side):
            if m.first_stamp - SIDE_MATCH_SLACK_S <= closing <= m.last_stamp + SIDE_MATCH_SLACK_S:
                return self._side.pop(i)
        return None


def _joined_doubt(result: ShapeResult, score: float, threshold: float) -> str:
    """Why a normal score read on frames split from a neighbour's outline cannot pass the fillet ('' when it can):
    it lies within JOINED_MARGIN_LN above the cut, or the window was merged over JOINED_MERGED_FRAMES frames or
    lost frames."""
    if not result.joined_at_line:
        return ""
    if math.log(score / threshold) < JOINED_MARGIN_LN:
        return REASON_JOINED.format(score, math.expm1(JOINED_MARGIN_LN), threshold)
    if result.rejected_frames >= JOINED_MERGED_FRAMES or result.window_gap_s > 0.0:
        return REASON_JOINED_THROUGH.format(result.rejected_frames, result.window_gap_s)
    return ""


def _outline(contour: np.ndarray) -> np.ndarray:
    return np.asarray(contour, dtype=np.int32).reshape(-1, 2)


def _area(contour: np.ndarray) -> float:
    return float(cv2.contourArea(_outline(contour)))
