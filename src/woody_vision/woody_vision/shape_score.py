"""The paper's top-down shape score Φ, evaluated per tracked fillet as it bends over the roller edge.

Per track, :class:`ShapeEvaluator` runs a small state machine on the fillet's
contour, frame by frame (flow = +v, the roller edge is the image row ``edge_row``):

1. approaching: remember the latest contour whose leading edge (max v) is still
   short of ``edge_row - reference_margin_px``;
2. when the leading edge reaches the edge, that remembered contour becomes the
   reference: its tip-cut body H_ref, min-area-rect aspect ratio AR (≥ 1),
   solidity S_ref and the offset from the body's trailing edge (min v) to its
   centroid, locked while the fillet is still flat;
3. every frame from then on (this one included): cut the current contour the
   same way and score Φ_t = w1·D(H_ref, H_cur)/AR + w2·|S_ref − S_cur|, with D
   ``cv2.matchShapes`` I1; keep the maximum and its two unweighted terms;
4. the window closes on the first frame where the virtual centroid (current
   body trailing edge + locked offset) is at or past the edge; that frame is
   scored too, since it is the observation nearest the crossing moment.

A result is produced exactly once per evaluator: 'scored' when the window
closes, otherwise 'unscored' with a reason (no reference because the track
started at or past the edge, or the track ended before the window closed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import Enum

import cv2
import numpy as np

from woody_vision.tracking import TrackUpdate

W1 = 100.0
"""Weight of the Hu-moment term (paper)."""
W2 = 100.0
"""Weight of the solidity term (paper)."""
TIP_WIDTH_RATIO = 0.30
"""Ends narrower than this fraction of the widest row are cut off (paper: 30 %)."""
DEFAULT_REFERENCE_MARGIN_PX = 2.0

STATUS_SCORED = "scored"
STATUS_UNSCORED = "unscored"
REASON_STARTED_PAST_EDGE = "no reference: track started with its leading edge at or past the roller edge"
REASON_LOST_BEFORE_EDGE = "track ended before reaching the roller edge"
REASON_LOST_IN_WINDOW = "track ended before the evaluation window closed"
REASON_DEGENERATE = "degenerate reference contour"


def cut_tip(contour: np.ndarray, flow_axis: str = "v", tip_ratio: float = TIP_WIDTH_RATIO) -> np.ndarray:
    """Body contour with both ends cut where the transverse width falls below ``tip_ratio`` × max width.

    The contour is rasterised and its width (filled pixels per line across the
    flow) is walked from the widest line towards each end; the body keeps the
    lines up to, not including, the first one narrower than the limit. Returns a
    (K, 2) int32 contour in the input's coordinates (the input itself if it
    encloses no pixels).
    """
    if flow_axis not in ("u", "v"):
        raise ValueError(f"flow_axis must be 'u' or 'v', got {flow_axis!r}")
    points = np.asarray(contour, dtype=np.int32).reshape(-1, 2)
    if flow_axis == "u":
        points = points[:, ::-1]
    origin = points.min(axis=0)
    size = points.max(axis=0) - origin + 1
    mask = np.zeros((int(size[1]), int(size[0])), np.uint8)
    cv2.fillPoly(mask, [points - origin], 255)
    widths = np.count_nonzero(mask, axis=1)
    peak = int(np.argmax(widths))
    narrow = widths < tip_ratio * widths[peak]
    before = np.flatnonzero(narrow[:peak])
    after = np.flatnonzero(narrow[peak:])
    first = int(before[-1]) + 1 if before.size else 0
    last = peak + int(after[0]) if after.size else mask.shape[0]
    mask[:first] = 0
    mask[last:] = 0
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        return np.asarray(contour, dtype=np.int32).reshape(-1, 2)
    body = max(contours, key=cv2.contourArea).reshape(-1, 2) + origin
    if flow_axis == "u":
        body = body[:, ::-1]
    return np.ascontiguousarray(body, dtype=np.int32)


def solidity(contour: np.ndarray) -> float:
    """Contour area over convex-hull area (1 for convex shapes, 0 for degenerate ones)."""
    hull_area = cv2.contourArea(cv2.convexHull(contour))
    return cv2.contourArea(contour) / hull_area if hull_area > 0.0 else 0.0


def aspect_ratio(contour: np.ndarray) -> float:
    """Long over short side of the minimum-area rectangle (≥ 1; inf for a line)."""
    (_, _), (w, h), _ = cv2.minAreaRect(contour)
    short, long = sorted((w, h))
    return long / short if short > 0.0 else math.inf


@dataclass(frozen=True)
class ShapeReference:
    """The flat fillet's body, locked just before it reaches the edge."""

    body: np.ndarray
    aspect_ratio: float
    solidity: float
    centroid_offset_px: float
    """Body centroid row minus body trailing-edge row (min v)."""


def make_reference(contour: np.ndarray, tip_ratio: float = TIP_WIDTH_RATIO) -> ShapeReference | None:
    """Reference measures of a flat fillet's contour, or None if its body has no area."""
    body = cut_tip(contour, "v", tip_ratio)
    moments = cv2.moments(body)
    if moments["m00"] <= 0.0:
        return None
    ratio = aspect_ratio(body)
    if not math.isfinite(ratio):
        return None
    return ShapeReference(
        body=body,
        aspect_ratio=ratio,
        solidity=solidity(body),
        centroid_offset_px=moments["m01"] / moments["m00"] - float(body[:, 1].min()),
    )


def shape_terms(reference: ShapeReference, body: np.ndarray) -> tuple[float, float]:
    """Unweighted (D/AR, |S_ref − S_cur|) of a current body against the reference."""
    distance = cv2.matchShapes(reference.body, body, cv2.CONTOURS_MATCH_I1, 0.0)
    return distance / reference.aspect_ratio, abs(reference.solidity - solidity(body))


@dataclass(frozen=True)
class ShapeResult:
    """Outcome of one fillet's evaluation window."""

    status: str
    """'scored' or 'unscored'."""
    reason: str
    """Why it is unscored ('' when scored)."""
    phi: float
    """Max Φ over the window (NaN if no frame was scored)."""
    hu_term: float
    """D/AR at the max-Φ frame (unweighted: Φ = w1·hu_term + w2·solidity_term)."""
    solidity_term: float
    """|S_ref − S_cur| at the max-Φ frame (unweighted)."""
    frames: int
    """Frames scored in the window."""
    stamp: float | None
    """Stamp of the closing frame (the last seen frame if unscored)."""
    aspect_ratio: float
    """Reference AR (NaN without a reference)."""
    track_id: int = -1
    lane: int = -1
    reference_stamp: float | None = None
    """Stamp of the reference frame (the last flat frame before the leading edge reached the roller edge)."""


class _Phase(Enum):
    APPROACHING = "approaching"
    IN_WINDOW = "in_window"
    DONE = "done"


class ShapeEvaluator:
    """Per-track state machine producing one :class:`ShapeResult` (see the module doc)."""

    def __init__(
        self,
        edge_row: float,
        w1: float = W1,
        w2: float = W2,
        tip_ratio: float = TIP_WIDTH_RATIO,
        reference_margin_px: float = DEFAULT_REFERENCE_MARGIN_PX,
    ) -> None:
        if not 0.0 < tip_ratio < 1.0:
            raise ValueError(f"tip_ratio must be in (0, 1), got {tip_ratio}")
        if reference_margin_px < 0.0:
            raise ValueError(f"reference_margin_px must be >= 0, got {reference_margin_px}")
        self.edge_row = float(edge_row)
        self.w1 = float(w1)
        self.w2 = float(w2)
        self.tip_ratio = float(tip_ratio)
        self.reference_margin_px = float(reference_margin_px)
        self._phase = _Phase.APPROACHING
        self._last_flat: np.ndarray | None = None
        self._last_flat_stamp: float | None = None
        self._reference: ShapeReference | None = None
        self._best = (math.nan, math.nan, math.nan)
        self._frames = 0
        self._last_stamp: float | None = None

    @property
    def done(self) -> bool:
        """True once the result has been produced."""
        return self._phase is _Phase.DONE

    def update(self, contour: np.ndarray, stamp: float) -> ShapeResult | None:
        """Feed this frame's full contour; returns the result on the frame it is decided."""
        if self._phase is _Phase.DONE:
            return None
        self._last_stamp = stamp
        points = np.asarray(contour, dtype=np.int32).reshape(-1, 2)
        if self._phase is _Phase.APPROACHING:
            if float(points[:, 1].max()) < self.edge_row - self.reference_margin_px:
                self._last_flat, self._last_flat_stamp = points, stamp
                return None
            if self._last_flat is None:
                return self._finish(STATUS_UNSCORED, REASON_STARTED_PAST_EDGE)
            self._reference = make_reference(self._last_flat, self.tip_ratio)
            self._last_flat = None
            if self._reference is None:
                return self._finish(STATUS_UNSCORED, REASON_DEGENERATE)
            self._phase = _Phase.IN_WINDOW
        reference = self._reference
        body = cut_tip(points, "v", self.tip_ratio)
        hu_term, solidity_term = shape_terms(reference, body)
        phi = self.w1 * hu_term + self.w2 * solidity_term
        self._frames += 1
        if not phi <= self._best[0]:  # also true while the best is still NaN
            self._best = (phi, hu_term, solidity_term)
        virtual_centroid = float(body[:, 1].min()) + reference.centroid_offset_px
        if virtual_centroid >= self.edge_row:
            return self._finish(STATUS_SCORED, "")
        return None

    def finish(self) -> ShapeResult | None:
        """The track ended: the unscored result, or None if a result was already produced."""
        if self._phase is _Phase.DONE:
            return None
        reason = REASON_LOST_BEFORE_EDGE if self._phase is _Phase.APPROACHING else REASON_LOST_IN_WINDOW
        return self._finish(STATUS_UNSCORED, reason)

    def _finish(self, status: str, reason: str) -> ShapeResult:
        self._phase = _Phase.DONE
        phi, hu_term, solidity_term = self._best
        return ShapeResult(
            status=status,
            reason=reason,
            phi=phi,
            hu_term=hu_term,
            solidity_term=solidity_term,
            frames=self._frames,
            stamp=self._last_stamp,
            aspect_ratio=self._reference.aspect_ratio if self._reference is not None else math.nan,
            reference_stamp=self._last_flat_stamp if self._reference is not None else None,
        )


class ShapeScorer:
    """Runs one :class:`ShapeEvaluator` per track of a :class:`~woody_vision.tracking.CentroidTracker`."""

    def __init__(self, edge_row: float, **evaluator_options: float) -> None:
        self.edge_row = float(edge_row)
        self._options = evaluator_options
        ShapeEvaluator(self.edge_row, **evaluator_options)  # validate the options now, not on the first track
        self._evaluators: dict[int, ShapeEvaluator] = {}

    def reset(self) -> None:
        """Forget every track's evaluation."""
        self._evaluators.clear()

    def update(self, tracks: TrackUpdate, stamp: float) -> list[ShapeResult]:
        """Feed the tracks seen this frame and close the ended ones; returns the results decided now."""
        results: list[ShapeResult] = []
        for track in tracks.active:
            if track.unseen:
                continue
            evaluator = self._evaluators.get(track.track_id)
            if evaluator is None:
                evaluator = self._evaluators[track.track_id] = ShapeEvaluator(self.edge_row, **self._options)
            result = evaluator.update(track.blob.contour, stamp)
            if result is not None:
                results.append(replace(result, track_id=track.track_id, lane=track.lane))
        for track in tracks.ended:
            evaluator = self._evaluators.pop(track.track_id, None)
            result = evaluator.finish() if evaluator is not None else None
            if result is not None:
                results.append(replace(result, track_id=track.track_id, lane=track.lane))
        return results
