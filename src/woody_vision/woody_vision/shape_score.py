"""The paper's top-down shape score Φ, evaluated per tracked fillet as it bends over the roller edge.

Per track, :class:`ShapeEvaluator` runs a small state machine on the fillet's
contour, frame by frame (flow = +v, the roller edge is the image row ``edge_row``;
the leading edge is the contour's max v, the trailing edge its min v):

1. approaching: remember the latest contour whose leading edge is still short of
   ``edge_row - reference_margin_px``;
2. when the leading edge reaches that row, the remembered (flat) contour becomes
   the reference (:func:`make_reference`): its narrow leading end is cut off once
   (:func:`leading_cut_rows`), and the body's length L along the flow, its
   min-area-rect aspect ratio AR (≥ 1), its solidity S_ref and the offset from
   the trailing edge to its centroid are locked;
3. the window opens on the first frame whose rigid body front (trailing edge + L)
   reaches the edge. Every frame in it, the current body is the current contour
   clipped to the same span [trailing edge, trailing edge + L]
   (:func:`clip_body`) and scored Φ_t = w1·D(H_ref, H_cur)/AR + w2·|S_ref − S_cur|,
   D = ``cv2.matchShapes`` I1. The result keeps max Φ_t and, like the paper's
   "Hu Mo. Score" and "Sol. Diff." columns, each term's own maximum;
4. the window closes on the first frame where the virtual centroid (trailing
   edge + locked offset) is at or past the edge; that frame is scored too.
   If that frame is more than ``GAP_FRAMES`` frames of the fillet's own
   approach speed past the point (frames lost in a burst around the edge, a
   real camera's or network's dropped frames), it shows a fillet already
   falling off and would score it far too high: the result is unscored
   instead of wrong. Frames lost inside the window are found by stamp: a step
   between the fillet's sightings of more than ``GAP_FRAMES`` frame intervals
   (the approach's shortest step) into a window frame means Φ is a maximum over
   part of the window, so Φ and its terms are absent (NaN) with the reason, and
   a grader on the paper's Φ leaves the fillet unscored. Φ is only ever the
   maximum over a complete window: a window that did not close cleanly
   leaves it absent too.

Why the cut is fixed by the reference and not re-found per frame (as the seed
system does): the segmenter thresholds height above the empty scene, and past
the edge the empty scene is the floor, so a thin tip that was too low to
segment on the belt appears once it is over the edge. A per-frame width cut
then jumps and adds that tip to the body, a change that is the same for every
stiff fillet: it gave ``seed0002`` a Φ of about 12 at every k from 20 to 400.
Clipping every frame at the locked rigid front leaves anything that only
appears ahead of the body out of the score; only bending pulls the visible
body back inside the span.

The line score. Φ is a maximum over frames, and a compliant fillet's Φ_t climbs
5–7 per 30 Hz frame over the last frames of the window, so where the closing
frame happens to fall on that ramp (the line speed, which end leads, a turn)
moves a normal fillet's Φ a lot. The line therefore grades on ``line_phi``:
Φ_t interpolated at the moment the rigid overhang (trailing edge + L − edge)
is ``line_fraction`` × L, a physically equivalent moment for every fillet,
found between the two frames around it, on the rising envelope of Φ_t (each
frame capped by the lowest later frame, :func:`rising_envelope`): a fillet only
bends further as it tips, and a frame a neighbour's outline joined stands above
the frames after it. The evaluator keeps scoring past the
centroid crossing until that moment is passed and one frame more has confirmed
the frame past it (a fillet sent blunt end first has its centroid ahead of
mid-body, so its window closes earlier); a track that ends before that frame
is scored on the frames it has. It also
reports what the decision may depend on, all measured on the reference
outline and the approach: the fillet's speed in the image, which end leads
(:func:`leading_end`), how far it lies turned from the flow
(:func:`turn_deg`) and its body length.

Crowded lanes. A window frame whose outline suddenly grows (area or width
beyond ``MERGE_GROWTH`` × the reference's) or whose trailing edge jumps back
is a blob merged with a neighbour (a follower touching the fillet as it tips,
a fillet side by side in the next lane); one whose trailing edge lies ahead of
where the fillet's own should be by now is a piece of an outline (a track that
took a sliver split off at the edge); one whose centroid has moved across
the flow by more than ``LATERAL_JUMP_RATIO`` × the reference's width is
another fillet's blob (a track that switched fillets after a merge); one that
reaches beyond the reference's columns or length by more than ``SPILL_RATIO``
holds another fillet's outline (on the belt plane a fillet bending over the
roller only shortens along the flow). One whose scored body covers more than
``FOREIGN_SHARE`` of the fillet's area outside its own footprint riding the
belt holds a piece of another fillet (:func:`outside_share`), and near the
measuring point one into whose footprint a neighbour's outline reaches that
far lost a piece to it (:func:`intruding_share`). Each is rejected, never scored, and
counted. A frame whose outline touches another fillet's is scored and marked
joined (``JOIN_MIN_POINTS``): the split between them is a guess, and the
grader decides what such a score may decide. If the frames left around the
measuring point are too far apart, the point is read on the line through the two clean frames nearest it on
one side (:func:`extrapolate_at`) when the nearer lies within a frame's advance of it; else the fillet is
unscored with the reason. The reference is likewise the latest
flat outline not grown beyond ``MERGE_GROWTH`` × the median flat area.

Two outlines. On a line the evaluator follows the fillet's outline on the belt plane
(woody_vision.camera_model.belt_outline: what a camera off the fillet's axis sees of a
part hanging over the roller, moved back to where it hangs), which decides the window and
``line_phi``; the paper's Φ and its two terms are measured, as the paper measures them,
on the outline in the image, against a reference made from the image outline of the same
flat frame and clipped from its own trailing edge.

A result is produced exactly once per evaluator: 'scored' when the window
closes, otherwise 'unscored' with a reason (no reference because the track
started at or past the edge, the track ended before the window closed, or the
fillet is overdue: by its own speed its centroid lies further past the edge
than a late frame may close the window, and no frame closed it). An overdue
fillet is decided on the frame that shows it (:meth:`ShapeEvaluator.overdue`),
not when the tracker gives its track up half a second later: the gate
downstream still gets the verdict in time.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from enum import Enum

import cv2
import numpy as np

from woody_vision.frame_checks import GAP_FRAMES, frame_interval, is_gap

W1 = 100.0
"""Weight of the Hu-moment term (paper)."""
W2 = 100.0
"""Weight of the solidity term (paper)."""
TIP_WIDTH_RATIO = 0.30
"""The leading end is cut up to the first line at least this fraction of the widest line (paper: 30 %)."""
DEFAULT_REFERENCE_MARGIN_PX = 2.0

STATUS_SCORED = "scored"
STATUS_UNSCORED = "unscored"
REASON_STARTED_PAST_EDGE = "no reference: track started with its leading edge at or past the roller edge"
REASON_LOST_BEFORE_EDGE = "track ended before its body reached the roller edge"
REASON_LOST_IN_WINDOW = "track ended before the evaluation window closed"
REASON_DEGENERATE = "degenerate reference contour"
REASON_LATE_CLOSE = "frames lost at the roller edge: the window closed {:.0f} px past the fillet's centroid"
REASON_WINDOW_GAP = "phi absent: frames lost in the evaluation window ({:.3f} s without a frame of this fillet)"
REASON_OVERDUE_BEFORE_EDGE = ("fillet not seen since before the roller edge, and by its speed its centroid is past "
                              "it: unscored while the gate can still act")
REASON_OVERDUE_IN_WINDOW = ("no clean frame closed the evaluation window, and by its speed the fillet's centroid is "
                            "{:.0f} px past the roller edge: unscored while the gate can still act")
REASON_LINE_GAP = ("no clean frames around the measuring point (overhang {:.2f} L): frames lost or merged with a "
                   "neighbour ({} rejected)")
MIN_SIGHTINGS = 3
"""Frames a fillet must be seen in before any verdict on it: a track seen once or twice is a piece a split cut off
a blob for a frame or two (at the edge, where fillets merge as they tip), a fillet's first sightings at the image
border before a burst of lost frames, or noise, and gives none, like a tentative track in SORT-style trackers. A
track first seen past the edge gets its unscored verdict ("no reference") on its third frame."""
LINE_OVERHANG_FRACTION = 0.5
"""The line score is Φ_t where the rigid overhang is this fraction of the body length L (before a narrow-first
fillet's centroid crosses the edge, about at a blunt-first one's)."""
MERGE_GROWTH = 1.25
"""A window frame whose outline area or width exceeds the reference's by this factor is a merged blob."""
LATERAL_JUMP_RATIO = 0.4
"""A window frame whose centroid lies this far across the flow (× the reference width) from the reference's
belongs to another fillet: fillets move along the flow, and draping shifts the centroid far less."""
FLAT_OVERLAP_MIN = 0.8
"""A window frame whose part still on the belt overlaps the reference outline, moved with the belt, by less than
this (intersection over union) is not this fillet alone: a neighbour's outline joined to it, or a split of a
merged blob cut a piece off it (:func:`flat_overlap`). The part on the belt lies flat, so it keeps its outline."""
FLAT_MARGIN_PX = 4
"""Rows before the roller edge left out of the flat part: the fillet starts to bend there."""
FLAT_MIN_SHARE = 0.2
"""The flat part is compared while the reference's part on the belt is at least this share of its area."""
TRAILING_JUMP_PX = 3
"""A window frame whose trailing edge lies this far behind the previous frame's belongs to a merged follower."""
TRAILING_LEAP_RATIO = 0.2
"""A window frame whose trailing edge lies this far (× the body length) ahead of where the fillet's own trailing
edge should be (:meth:`ShapeEvaluator.predicted_trailing`) is a piece of an outline, not the fillet: the part of
a tipping fillet still on the belt rides it at the belt's speed. A track that starts past the edge with its
trailing edge within this of a lane-mate's prediction is that fillet again (woody_vision.grader_core)."""
SPILL_RATIO = 0.1
"""A window frame whose outline reaches across the flow beyond the reference's columns, or along it beyond the
reference's extent, by more than this fraction of the reference's width or extent holds another fillet's outline:
a fillet bending over the roller only shortens along the flow, and keeps its columns, on the belt plane."""
FOOTPRINT_TOLERANCE_PX = 3
"""How far (px) a window frame's outline may reach outside the fillet's own footprint riding the belt
(:func:`outside_share`): the trailing edge it is moved by is good to a pixel or two, and a thin rim too low to
segment on the belt shows over the floor past the edge."""
FOREIGN_SHARE = 0.015
"""A window frame whose scored body covers more than this share of the fillet's area outside its own footprint
riding the belt holds a piece of another fillet, and is rejected: a fillet alone stays inside it (on the live
line's uncrowded messy runs, 0.7 % at most of any window frame), while 3.5 % of a normal neighbour's hanging part
joined to a stiff fillet tripled its score. Within JOIN_SPAN of the measuring point a frame is rejected too when a
neighbour's outline covers this share inside the fillet's footprint: the split gave the neighbour a piece of it
(a stiff fillet missing a piece of its hanging part scored 20 against a cut of 5)."""
JOIN_PX = 2
"""Outline points this close (px, along rows or columns) to another fillet's outline touch it."""
JOIN_MIN_POINTS = 20
"""A window frame whose outline touches another fillet's over this many points was split from the two fillets'
joined blob (:func:`touches`): where the split falls is a guess, on the belt as in the part hanging over the
roller, and Φ_t measures the whole outline, so it may hold a piece of the neighbour or miss a piece of its own.
The frame is scored and marked (``FrameScore.joined``); the grader decides what a score read on such frames may
decide."""
JOIN_SPAN = 0.15
"""A line score is read on joined frames when a frame within this much overhang (× L) of the measuring point was
joined (``ShapeResult.joined_at_line``)."""
CONTAMINATED_RATIO = 0.5
"""A window frame whose Φ_t the rising envelope lowers below this fraction of it carried a neighbour's outline that
the merge tests above missed: it is rejected when the line score is read. Lowered instead, it would take the value
of a later frame, further along the rise, at its own earlier overhang. A fillet's own Φ_t seldom dips that far:
headless, with no neighbour to join it, 59 of 5,400 evaluations had such a frame, and 2 line scores moved by 4 % or
less."""
CONTAMINATED_MIN_PHI = 1.0
"""...and by at least this much: a fillet still flat scores about 0, and its Φ_t's dips are large fractions of it."""
LEADING_NARROW = "narrow"
LEADING_BLUNT = "blunt"
FLAT_HISTORY = 8
"""Flat outlines kept to choose an unmerged reference from."""
SPEED_FRAMES = 8
"""Flat frames the fillet's speed is measured over (0.23 s at 30 Hz: about 100 rows at 100 FPM, so a pixel of
outline noise moves it by about 1 %, and a belt speed change is followed within that many frames)."""


def fill_rows(contour: np.ndarray) -> tuple[np.ndarray, int, int]:
    """The contour rasterised in its bounding box: (mask, first row v, first column u)."""
    points = np.asarray(contour, dtype=np.int32).reshape(-1, 2)
    u0, v0 = (int(x) for x in points.min(axis=0))
    size = points.max(axis=0) - (u0, v0) + 1
    mask = np.zeros((int(size[1]), int(size[0])), np.uint8)
    cv2.fillPoly(mask, [points - (u0, v0)], 255)
    return mask, v0, u0


def leading_cut_rows(widths: np.ndarray, tip_ratio: float = TIP_WIDTH_RATIO) -> int:
    """Rows to cut off the leading (last) end of a width profile.

    Scanning from the leading end, the cut keeps the first row at least
    ``tip_ratio`` × the widest row and everything behind it. A cut longer than
    half the fillet is not a tip but an odd outline, and is ignored (0).
    """
    widths = np.asarray(widths)
    if widths.size == 0 or widths.max() <= 0:
        return 0
    cut = int(np.argmax(widths[::-1] >= tip_ratio * widths.max()))
    return cut if 2 * cut <= widths.size else 0


def clip_body(contour: np.ndarray, trailing_row: int, length_px: int) -> np.ndarray:
    """The contour's part between rows ``trailing_row`` and ``trailing_row + length_px`` (inclusive).

    Returns the largest outer contour of that part as (K, 2) int32 in the input's
    coordinates, or an empty (0, 2) array if nothing of the contour lies there.
    """
    mask, v0, u0 = fill_rows(contour)
    first = max(0, int(trailing_row) - v0)
    last = int(trailing_row) + int(length_px) - v0 + 1
    mask[:first] = 0
    mask[max(last, 0):] = 0
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        return np.zeros((0, 2), np.int32)
    body = max(contours, key=cv2.contourArea).reshape(-1, 2) + (u0, v0)
    return np.ascontiguousarray(body, dtype=np.int32)


def solidity(contour: np.ndarray) -> float:
    """Contour area over convex-hull area (1 for convex shapes, 0 for degenerate ones)."""
    if len(contour) < 3:
        return 0.0
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
    """Body centroid row minus trailing-edge row (min v)."""
    length_px: int
    """Body length along the flow: last body row minus trailing-edge row. Trailing edge + this = the rigid front."""


def make_reference(contour: np.ndarray, tip_ratio: float = TIP_WIDTH_RATIO) -> ShapeReference | None:
    """Reference measures of a flat fillet's contour with its narrow leading end cut, or None if degenerate."""
    points = np.asarray(contour, dtype=np.int32).reshape(-1, 2)
    mask, trailing, _ = fill_rows(points)
    length = mask.shape[0] - 1 - leading_cut_rows(np.count_nonzero(mask, axis=1), tip_ratio)
    body = clip_body(points, trailing, length)
    moments = cv2.moments(body) if len(body) >= 3 else {"m00": 0.0}
    if moments["m00"] <= 0.0:
        return None
    ratio = aspect_ratio(body)
    if not math.isfinite(ratio):
        return None
    return ShapeReference(
        body=body,
        aspect_ratio=ratio,
        solidity=solidity(body),
        centroid_offset_px=moments["m01"] / moments["m00"] - trailing,
        length_px=length,
    )


def shape_terms(reference: ShapeReference, body: np.ndarray) -> tuple[float, float]:
    """Unweighted (D/AR, |S_ref − S_cur|) of a current body against the reference."""
    distance = cv2.matchShapes(reference.body, body, cv2.CONTOURS_MATCH_I1, 0.0)
    return distance / reference.aspect_ratio, abs(reference.solidity - solidity(body))


@dataclass(frozen=True)
class FrameScore:
    """One scored frame of a window (for traces): Φ_t and its two unweighted terms."""

    stamp: float
    phi: float
    hu_term: float
    solidity_term: float
    overhang: float = math.nan
    """Rigid overhang (trailing edge + L − edge) as a fraction of the body length L."""
    joined: bool = False
    """The outline touched another fillet's (JOIN_MIN_POINTS)."""


@dataclass(frozen=True)
class ShapeResult:
    """Outcome of one fillet's evaluation window."""

    status: str
    """'scored' or 'unscored'."""
    reason: str
    """Why it is unscored, or why ``phi`` is absent when it is scored on ``line_phi`` ('' otherwise)."""
    phi: float
    """Max Φ_t over the complete window (NaN unless the window closed cleanly without a gap)."""
    hu_term: float
    """Max over the complete window of D/AR, its own maximum (paper's "Hu Mo. Score"; not necessarily at the
    max-Φ frame, so Φ ≤ w1·hu_term + w2·solidity_term)."""
    solidity_term: float
    """Max over the complete window of |S_ref − S_cur|, its own maximum (paper's "Sol. Diff."); NaN like ``phi``."""
    frames: int
    """Frames scored in the window."""
    stamp: float | None
    """When the fillet's centroid crossed the roller edge, or by its speed was due there (:meth:`ShapeEvaluator.
    crossing_stamp`); the last seen frame's stamp when the fillet had no reference or speed. The gate times its
    diverter from it, so it is the crossing whenever the result is decided: on the closing frame, frames later (a
    blunt-first fillet, frames merged after the close), or when the fillet went unseen."""
    aspect_ratio: float
    """Reference AR (NaN without a reference)."""
    track_id: int = -1
    lane: int = -1
    reference_stamp: float | None = None
    """Stamp of the reference frame (the last flat frame before the leading edge reached the roller edge)."""
    trace: tuple[FrameScore, ...] = ()
    """Every scored frame of the window, in order (the outline the evaluator follows)."""
    paper_trace: tuple[FrameScore, ...] = ()
    """The same frames scored on the image outline (the paper's Φ_t; equal to ``trace`` without one)."""
    line_phi: float = math.nan
    """Φ_t at the overhang ``line_fraction`` × L, interpolated between the frames around it: the line's score."""
    line_fraction: float = LINE_OVERHANG_FRACTION
    leading_end: str = ""
    """'narrow' or 'blunt': which end of the reference outline leads (:func:`leading_end`)."""
    speed_px_s: float = math.nan
    """The fillet's speed along the image rows while flat (px/s)."""
    turn_deg: float = math.nan
    """How far the reference outline's long axis lies turned from the flow (0..90 degrees, :func:`turn_deg`)."""
    length_px: float = math.nan
    """The reference body's length along the flow (px)."""
    rejected_frames: int = 0
    """Window frames rejected as merged with a neighbour."""
    reference_contour: np.ndarray | None = None
    """The flat outline the reference was made from (for overlays)."""
    line_contour: np.ndarray | None = None
    """The outline of the frame nearest the measuring point (for overlays)."""
    line_stamp: float | None = None
    """Stamp of that frame."""
    extra_trace: tuple[FrameScore, ...] = ()
    """Frames scored after the window closed, up to the measuring point."""
    window_closed: bool = False
    """Whether the paper's window closed cleanly and without a gap, so that ``phi`` is the paper's Φ."""
    window_gap_s: float = 0.0
    """The longest step into a window frame that lost frames before it (s; 0 when none was lost)."""
    line_bounds: tuple[float, float] = (0.0, math.inf)
    """Where no two frames read the measuring point (REASON_LINE_GAP): the least and the most Φ_t there can be, the
    rising envelope of the fillet's own frames before (unjoined) and past it however far apart (:func:`bracket_at`)."""

    @property
    def joined_at_line(self) -> bool:
        """Whether a frame within JOIN_SPAN of the measuring point was split from a neighbour's outline."""
        frames = self.trace + self.extra_trace
        return any(f.joined and abs(f.overhang - self.line_fraction) <= JOIN_SPAN for f in frames)


def flat_overlap(reference: np.ndarray, current: np.ndarray, shift_rows: int, last_row: int) -> float:
    """Intersection over union of two outlines' parts at rows up to ``last_row``, the reference moved
    ``shift_rows`` down the flow (NaN when the reference's part there is under FLAT_MIN_SHARE of its area)."""
    ref_mask, ref_v, ref_u = fill_rows(reference)
    cur_mask, cur_v, cur_u = fill_rows(current)
    ref_v += int(shift_rows)
    top, left = min(ref_v, cur_v), min(ref_u, cur_u)
    rows = last_row - top + 1
    if rows <= 0:
        return math.nan
    width = max(ref_u + ref_mask.shape[1], cur_u + cur_mask.shape[1]) - left
    canvas = np.zeros((2, rows, width), bool)
    for layer, (mask, v, u) in enumerate(((ref_mask, ref_v, ref_u), (cur_mask, cur_v, cur_u))):
        part = mask[: max(0, last_row - v + 1)] > 0
        canvas[layer, v - top: v - top + part.shape[0], u - left: u - left + part.shape[1]] = part
    if canvas[0].sum() < FLAT_MIN_SHARE * np.count_nonzero(ref_mask):
        return math.nan
    return float(np.logical_and(*canvas).sum() / np.logical_or(*canvas).sum())


def outside_share(reference: np.ndarray, current: np.ndarray, shift_rows: int,
                  tolerance_px: int = FOOTPRINT_TOLERANCE_PX) -> float:
    """The share of the reference outline's area that ``current`` covers outside the reference moved ``shift_rows``
    down the flow and grown by ``tolerance_px``: on the belt plane a fillet bending over the roller only shortens
    along the flow, keeping each part's column, so its outline stays inside its own footprint riding the belt, and
    what lies outside is another fillet's."""
    inside, total, reference_area = _in_footprint(reference, current, shift_rows, tolerance_px)
    return (total - inside) / reference_area


def intruding_share(reference: np.ndarray, other: np.ndarray, shift_rows: int, last_row: int,
                    tolerance_px: int = FOOTPRINT_TOLERANCE_PX) -> float:
    """The share of the reference outline's area that another fillet's outline ``other`` covers, up to row
    ``last_row`` (this fillet's own leading edge now), inside the reference moved ``shift_rows`` down the flow and
    shrunk by ``tolerance_px``. Fillets' footprints never overlap, so a neighbour whose outline reaches into this
    one's beside it holds a piece of it (the split of their joined blob gave it one), and this fillet's outline
    misses that piece. Ahead of the fillet's own leading edge the lane-mate hanging ahead, drawn back towards the
    edge, may lie where this fillet's rigid footprint reaches past the edge: that is not counted."""
    limited = np.asarray(other).reshape(-1, 2).copy()
    limited[:, 1] = np.minimum(limited[:, 1], last_row)
    inside, _, reference_area = _in_footprint(reference, limited, shift_rows, -tolerance_px)
    return inside / reference_area


def _in_footprint(reference: np.ndarray, outline: np.ndarray, shift_rows: int,
                  grow_px: int) -> tuple[int, int, int]:
    """(pixels of ``outline`` inside the reference moved ``shift_rows`` and grown by ``grow_px`` (shrunk when
    negative), pixels of ``outline``, pixels of the reference)."""
    ref_mask, ref_v, ref_u = fill_rows(reference)
    cur_mask, cur_v, cur_u = fill_rows(outline)
    pad = abs(grow_px)
    ref_v += int(shift_rows) - pad
    ref_u -= pad
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * pad + 1, 2 * pad + 1))
    padded = cv2.copyMakeBorder(ref_mask, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=0)
    footprint = cv2.dilate(padded, kernel) if grow_px >= 0 else cv2.erode(padded, kernel)
    top, left = max(ref_v, cur_v), max(ref_u, cur_u)
    bottom = min(ref_v + footprint.shape[0], cur_v + cur_mask.shape[0])
    right = min(ref_u + footprint.shape[1], cur_u + cur_mask.shape[1])
    inside = 0
    if bottom > top and right > left:
        inside = np.count_nonzero(cur_mask[top - cur_v:bottom - cur_v, left - cur_u:right - cur_u]
                                  & footprint[top - ref_v:bottom - ref_v, left - ref_u:right - ref_u])
    return inside, np.count_nonzero(cur_mask), max(np.count_nonzero(ref_mask), 1)


def touches(outline: np.ndarray, others: Sequence[np.ndarray]) -> bool:
    """Whether ``outline`` touches one of ``others`` (JOIN_PX) at JOIN_MIN_POINTS points or more."""
    if len(outline) < JOIN_MIN_POINTS:
        return False
    low, high = outline.min(axis=0) - JOIN_PX, outline.max(axis=0) + JOIN_PX
    for other in others:
        near = other[np.all((other >= low) & (other <= high), axis=1)]
        if len(near) == 0:
            continue
        distance = np.abs(outline[:, None, :] - near[None, :, :]).max(axis=2).min(axis=1)
        if np.count_nonzero(distance <= JOIN_PX) >= JOIN_MIN_POINTS:
            return True
    return False


def leading_end(contour: np.ndarray) -> str:
    """'blunt' when the leading quarter of the outline holds more area than the trailing quarter.

    A fillet's narrow (tapered) end is the one with less surface. The quarters
    are taken along the outline's own long axis, pointed downstream (+v), not
    along the image rows: a fillet turned 30-45 degrees has rows that cut
    across both ends, and a row-wise comparison reads some narrow-first
    fillets as blunt first.
    """
    mask, _, _ = fill_rows(contour)
    rows, columns = np.nonzero(mask)
    points = np.stack([columns, rows], axis=1).astype(float)
    points -= points.mean(axis=0)
    eigenvalues, eigenvectors = np.linalg.eigh(points.T @ points)
    axis = eigenvectors[:, np.argmax(eigenvalues)]
    along = points @ (axis if axis[1] >= 0.0 else -axis)
    quarter = 0.25 * (along.max() - along.min())
    leading = np.count_nonzero(along >= along.max() - quarter)
    trailing = np.count_nonzero(along <= along.min() + quarter)
    return LEADING_BLUNT if leading > trailing else LEADING_NARROW


def rising_envelope(frames: list[FrameScore]) -> list[FrameScore]:
    """The frames with each Φ_t capped by the lowest Φ_t of the frames after it.

    A fillet's outline only deforms further as it tips over the edge, so its Φ_t rises (or stays) from frame to
    frame, and a rising sequence is its own envelope: an uncontaminated line score is unchanged. A frame in which a
    neighbour's outline joined the fillet's, or a split cut a piece off it, differs from the reference by more than
    the fillet's own bending: it stands above a later frame and is brought down to it, however many frames in a
    row were contaminated. Contamination only ever adds to Φ_t, so the lower value is the fillet's own."""
    out = list(frames)
    lowest = math.inf
    for i in range(len(frames) - 1, -1, -1):
        phi = frames[i].phi
        if math.isfinite(phi):
            lowest = min(lowest, phi)
            out[i] = replace(frames[i], phi=lowest)
    return out


def own_frames(frames: list[FrameScore]) -> tuple[list[int], list[FrameScore]]:
    """The indices of the frames the fillet's own outline scored, and their rising envelope: every frame but those
    the envelope lowers below `CONTAMINATED_RATIO` of their Φ_t (by more than `CONTAMINATED_MIN_PHI`)."""
    envelope = rising_envelope(frames)
    kept = [i for i, (frame, capped) in enumerate(zip(frames, envelope))
            if not (capped.phi < CONTAMINATED_RATIO * frame.phi and frame.phi - capped.phi > CONTAMINATED_MIN_PHI)]
    return kept, [envelope[i] for i in kept]


def interpolate_at(frames: list[FrameScore], fraction: float) -> tuple[float, int | None, float]:
    """Φ_t at the overhang ``fraction`` between the two frames around it, the index of the nearer one, and the
    overhang between those two frames (how far apart they are).

    (NaN, None, inf) when no two consecutive frames bracket it.
    """
    for i in range(1, len(frames)):
        before, after = frames[i - 1], frames[i]
        if before.overhang <= fraction <= after.overhang and after.overhang > before.overhang:
            gap = after.overhang - before.overhang
            weight = (fraction - before.overhang) / gap
            nearer = i if weight >= 0.5 else i - 1
            return before.phi + weight * (after.phi - before.phi), nearer, gap
    return math.nan, None, math.inf


def extrapolate_at(frames: list[FrameScore], fraction: float, step: float) -> tuple[float, int | None]:
    """Φ_t at the overhang ``fraction`` along the line through the two frames nearest it on one side, when the
    nearer lies within a frame's advance ``step`` of it and the two are no gap apart; and that frame's index. Φ_t
    is never below 0, nor is the value read (a steep line followed back can cross it).

    (NaN, None) when neither side has such a pair. Of two sides, the nearer frame's wins."""
    best: tuple[float, float, int | None] = (math.inf, math.nan, None)
    after = [i for i, f in enumerate(frames) if f.overhang >= fraction and math.isfinite(f.phi)][:2]
    before = [i for i, f in enumerate(frames) if f.overhang <= fraction and math.isfinite(f.phi)][-2:][::-1]
    for near, far in (pair for pair in (after, before) if len(pair) == 2):
        a, b = frames[near], frames[far]
        distance = abs(a.overhang - fraction)
        if distance <= step and not is_gap(abs(b.overhang - a.overhang), step) and distance < best[0]:
            slope = (b.phi - a.phi) / (b.overhang - a.overhang)
            best = (distance, max(0.0, a.phi + slope * (fraction - a.overhang)), near)
    return best[1], best[2]


def bracket_at(frames: list[FrameScore], fraction: float) -> tuple[float, float]:
    """The range Φ_t at the overhang ``fraction`` lies in, on a rising envelope ``frames`` however far apart they
    are: at least the last unjoined frame's at or before it (0 without one: Φ_t is never below 0), at most the
    first frame's at or past it (inf without one). A joined frame may hold a piece of its neighbour, which only
    ever raises Φ_t: it bounds the score from above, never from below (on the live line a stiff fillet's joined
    frame 0.2 L before its point scored 34 where the fillet alone scores 2)."""
    before = [f.phi for f in frames if f.overhang <= fraction and math.isfinite(f.phi) and not f.joined]
    after = [f.phi for f in frames if f.overhang >= fraction and math.isfinite(f.phi)]
    return (before[-1] if before else 0.0), (after[0] if after else math.inf)


def turn_deg(contour: np.ndarray) -> float:
    """Angle (0..90 degrees) between the outline's principal (long) axis and the flow (image rows).

    A fillet lying turned on the belt crosses the roller edge one corner
    first and drapes less at the same overhang; the decision can allow for it.
    """
    m = cv2.moments(np.asarray(contour, dtype=np.int32).reshape(-1, 1, 2))
    if m["m00"] <= 0.0:
        return math.nan
    axis_from_columns = 0.5 * math.degrees(math.atan2(2.0 * m["mu11"], m["mu20"] - m["mu02"]))
    return 90.0 - abs(axis_from_columns)


class _Phase(Enum):
    APPROACHING = "approaching"
    REFERENCED = "referenced"
    DONE = "done"


@dataclass(frozen=True)
class _FlatFrame:
    """A frame of the fillet lying flat before the edge: a candidate for its reference."""

    points: np.ndarray
    stamp: float
    area: float
    image: np.ndarray
    neighbours: Sequence[np.ndarray]
    """The other fillets' outlines of the same frame."""

    @property
    def joined(self) -> bool:
        """Its outline touched another fillet's (JOIN_MIN_POINTS): split from a joined blob, a guess at its outline.
        Asked of one frame only, when the reference is locked."""
        return touches(self.points, self.neighbours)


def most_typical(frames: Sequence[_FlatFrame]) -> _FlatFrame:
    """The flat frame whose outline overlaps the others' most (the sum of the intersections over union, each moved
    to its trailing edge; the latest on a tie): a fillet lying flat keeps its outline, and a frame whose split from
    a neighbour fell a few pixels off overlaps the others less."""
    def overlap(a: _FlatFrame, b: _FlatFrame) -> float:
        shift = int(b.points[:, 1].min()) - int(a.points[:, 1].min())
        return flat_overlap(a.points, b.points, shift, int(max(a.points[:, 1].max() + shift, b.points[:, 1].max())))
    scores = [sum(overlap(f, other) for other in frames if other is not f) for f in frames]
    return frames[len(scores) - 1 - int(np.argmax(scores[::-1]))]


class ShapeEvaluator:
    """Per-track state machine producing one :class:`ShapeResult` (see the module doc)."""

    def __init__(
        self,
        edge_row: float,
        w1: float = W1,
        w2: float = W2,
        tip_ratio: float = TIP_WIDTH_RATIO,
        reference_margin_px: float = DEFAULT_REFERENCE_MARGIN_PX,
        line_fraction: float = LINE_OVERHANG_FRACTION,
    ) -> None:
        if not 0.0 < tip_ratio < 1.0:
            raise ValueError(f"tip_ratio must be in (0, 1), got {tip_ratio}")
        if reference_margin_px < 0.0:
            raise ValueError(f"reference_margin_px must be >= 0, got {reference_margin_px}")
        if not 0.1 <= line_fraction <= 0.9:
            raise ValueError(f"line_fraction must be in [0.1, 0.9], got {line_fraction}")
        self.edge_row = float(edge_row)
        self.w1 = float(w1)
        self.w2 = float(w2)
        self.tip_ratio = float(tip_ratio)
        self.reference_margin_px = float(reference_margin_px)
        self.line_fraction = float(line_fraction)
        self._phase = _Phase.APPROACHING
        self._flat: list[_FlatFrame] = []
        """(contour, stamp, area, image outline) of the latest flat frames."""
        self._image_reference: ShapeReference | None = None
        self._paper_trace: list[FrameScore] = []
        self._reference: ShapeReference | None = None
        self._reference_contour: np.ndarray | None = None
        self._reference_stamp: float | None = None
        self._reference_area = math.nan
        self._reference_width = math.nan
        self._reference_column = math.nan
        self._trace: list[FrameScore] = []
        self._extra: list[FrameScore] = []
        self._contours: list[np.ndarray] = []
        self._closed = False
        self._last_trailing: int | None = None
        self._trailing_stamp = math.nan
        """When the fillet's own trailing edge was last seen (at ``_last_trailing``)."""
        self._rejected = 0
        self._last_stamp: float | None = None
        self._step = 0.0
        """Time since the previous sighting of this fillet (s)."""
        self._window_gap = 0.0
        """The longest step into a window frame that was a gap (s; 0 without one)."""
        self._sightings = 0
        self._approach: list[tuple[float, float]] = []
        """(stamp, leading row) of the flat frames: the fillet's own speed and frame interval in the image."""

    @property
    def done(self) -> bool:
        """True once the result has been produced."""
        return self._phase is _Phase.DONE

    @property
    def sightings(self) -> int:
        """Frames fed so far."""
        return self._sightings

    @property
    def last_frame(self) -> FrameScore | None:
        """The latest scored frame (None before the window opens): the Φ_t an overlay shows."""
        frames = self._extra or self._trace
        return frames[-1] if frames else None

    @property
    def reference_area(self) -> float:
        """Area (px²) of the flat outline the reference was made from (NaN before it is locked)."""
        return self._reference_area

    @property
    def flat_area(self) -> float:
        """Area (px²) of the fillet lying flat: the reference's once locked, before that the median of the flat
        frames seen so far (NaN before any)."""
        if self.referenced or not self._flat:
            return self._reference_area
        return float(np.median([f.area for f in self._flat]))

    @property
    def referenced(self) -> bool:
        """True once the fillet was seen flat before the edge and its reference is locked."""
        return self._reference is not None

    def update(self, contour: np.ndarray, stamp: float, image_contour: np.ndarray | None = None,
               neighbours: Sequence[np.ndarray] = ()) -> ShapeResult | None:
        """Feed this frame's full contour; returns the result on the frame it is decided.

        ``contour`` decides the window and ``line_phi`` (the belt outline on a line); ``image_contour``, the
        outline as the camera sees it (default: ``contour``), gives the paper's Φ, which the paper measures
        on the image. ``neighbours`` are the other fillets' outlines of this frame, like ``contour``."""
        if self._phase is _Phase.DONE:
            return None
        self._step = stamp - self._last_stamp if self._last_stamp is not None else 0.0
        self._last_stamp = stamp
        self._sightings += 1
        points = np.asarray(contour, dtype=np.int32).reshape(-1, 2)
        image = points if image_contour is None else np.asarray(image_contour, dtype=np.int32).reshape(-1, 2)
        if self._phase is _Phase.APPROACHING:
            if float(points[:, 1].max()) < self.edge_row - self.reference_margin_px:
                self._remember_flat(_FlatFrame(points, stamp, cv2.contourArea(points), image, tuple(neighbours)))
                return None
            if not self._flat:
                if self._sightings < MIN_SIGHTINGS:
                    return None  # a piece split off a blob past the edge lives a frame or two
                return self._finish(STATUS_UNSCORED, REASON_STARTED_PAST_EDGE)
            if not self._lock_reference():
                return self._finish(STATUS_UNSCORED, REASON_DEGENERATE)
            self._phase = _Phase.REFERENCED
        return self._window_frame(points, stamp, image, neighbours)

    def _remember_flat(self, frame: _FlatFrame) -> None:
        self._flat = (self._flat + [frame])[-FLAT_HISTORY:]
        self._see_trailing(int(frame.points[:, 1].min()), frame.stamp)
        self._approach.append((frame.stamp, float(frame.points[:, 1].max())))

    def _lock_reference(self) -> bool:
        """The reference from the latest flat outline not grown by a merge; False if it is degenerate. When that
        outline was split from a neighbour's (where a split falls is a guess, and a reference a few pixels off
        raises every frame's Φ_t), the most typical of the flat outlines instead (:func:`most_typical`)."""
        typical = float(np.median([f.area for f in self._flat]))
        clean = [f for f in self._flat if f.area <= MERGE_GROWTH * typical] or self._flat
        chosen = most_typical(clean) if clean[-1].joined else clean[-1]
        points, image = chosen.points, chosen.image
        self._reference_stamp, self._reference_area = chosen.stamp, chosen.area
        self._reference = make_reference(points, self.tip_ratio)
        self._image_reference = self._reference if image is points else make_reference(image, self.tip_ratio)
        self._reference_contour = points
        self._see_trailing(int(points[:, 1].min()), self._reference_stamp)
        self._reference_width = float(np.ptp(points[:, 0]) + 1)
        self._reference_column = _centroid_column(points)
        self._flat = []
        return self._reference is not None and self._image_reference is not None

    def _window_frame(self, points: np.ndarray, stamp: float, image: np.ndarray,
                      neighbours: Sequence[np.ndarray]) -> ShapeResult | None:
        reference = self._reference
        trailing = int(points[:, 1].min())
        if self._merged(points, trailing, stamp) or self._spills(points):
            return self._reject()
        self._see_trailing(trailing, stamp)
        if trailing + reference.length_px < self.edge_row:
            return None  # the rigid body front has not reached the edge yet: the window is not open
        body = clip_body(points, trailing, reference.length_px)
        overhang = (trailing + reference.length_px - self.edge_row) / reference.length_px
        near_line = abs(overhang - self.line_fraction) <= JOIN_SPAN
        if self._foreign(body, trailing) or (near_line and self._intruded(neighbours, points)):
            return self._reject()
        if not self._closed:
            self._note_gap()
        joined = touches(points, neighbours)
        frame = self._score(self._reference, body, stamp, overhang, joined)
        (self._extra if self._closed else self._trace).append(frame)
        self._contours.append(points)
        if not self._closed:
            self._paper_trace.append(frame if image is points else self._score_image(image, stamp, overhang))
            overshoot = trailing + reference.centroid_offset_px - self.edge_row
            if overshoot >= 0.0 and overshoot > GAP_FRAMES * self._advance_per_frame():
                return self._finish(STATUS_UNSCORED, REASON_LATE_CLOSE.format(overshoot))
            self._closed = overshoot >= 0.0
        if self._closed and self._confirmed():
            return self._finish_line()
        return None

    def _reject(self) -> None:
        """Count a window frame that is not this fillet alone; frames lost inside the window show as a gap."""
        self._rejected += 1
        if self._trace and not self._closed:
            self._note_gap()

    def _foreign(self, body: np.ndarray, trailing: int) -> bool:
        """Whether the scored body covers more than FOREIGN_SHARE of the fillet's area outside its own footprint
        riding the belt (:func:`outside_share`): a neighbour's outline joined to it."""
        shift = trailing - int(self._reference_contour[:, 1].min())
        return len(body) >= 3 and outside_share(self._reference_contour, body, shift) > FOREIGN_SHARE

    def _intruded(self, neighbours: Sequence[np.ndarray], points: np.ndarray) -> bool:
        """Whether another fillet's outline covers more than FOREIGN_SHARE of this one's area inside its footprint
        riding the belt, beside its outline ``points`` (:func:`intruding_share`): the split of their joined blob cut
        a piece off this one."""
        shift = int(points[:, 1].min()) - int(self._reference_contour[:, 1].min())
        leading = int(points[:, 1].max())
        return any(intruding_share(self._reference_contour, other, shift, leading) > FOREIGN_SHARE
                   for other in neighbours if len(other) >= 3)

    def _confirmed(self) -> bool:
        """Whether a frame has followed the first one at or past the measuring point: the rising envelope caps that
        frame by a later one, so a neighbour that joined its outline there does not set the score."""
        frames = self._trace + self._extra
        return len(frames) >= 2 and frames[-2].overhang >= self.line_fraction

    def _note_gap(self) -> None:
        """Remember the step into this window frame if frames were lost before it."""
        if is_gap(self._step, frame_interval([stamp for stamp, _ in self._approach])):
            self._window_gap = max(self._window_gap, self._step)

    def _see_trailing(self, trailing: int, stamp: float) -> None:
        self._last_trailing = trailing
        self._trailing_stamp = stamp

    def predicted_trailing(self, stamp: float) -> float:
        """The image row the fillet's own trailing edge should lie on at ``stamp``: its last one moved at the
        fillet's speed (NaN before two flat frames tell it)."""
        if self._last_trailing is None:
            return math.nan
        return self._last_trailing + self._speed_px_s() * (stamp - self._trailing_stamp)

    def continues_at(self, trailing: float, stamp: float) -> bool:
        """Whether an outline with this trailing edge at ``stamp`` is this referenced fillet's (see
        TRAILING_LEAP_RATIO)."""
        return self.referenced and abs(trailing - self.predicted_trailing(stamp)) <= self._leap_px()

    def lost_at(self, stamp: float) -> bool:
        """Whether this referenced fillet was not seen clean at ``stamp``: its track's frame then was rejected,
        its track was not seen, or its result is out (it is followed no more)."""
        return self.referenced and self._trailing_stamp < stamp

    def _leap_px(self) -> float:
        return TRAILING_LEAP_RATIO * self._reference.length_px

    def _merged(self, points: np.ndarray, trailing: int, stamp: float) -> bool:
        """Whether this window frame's blob has grown into a neighbour's or is a piece of an outline (see the
        module doc)."""
        if self._last_trailing is not None and trailing < self._last_trailing - TRAILING_JUMP_PX:
            return True
        if trailing > self.predicted_trailing(stamp) + self._leap_px():
            return True
        if abs(_centroid_column(points) - self._reference_column) > LATERAL_JUMP_RATIO * self._reference_width:
            return True
        width = float(np.ptp(points[:, 0]) + 1)
        grown = cv2.contourArea(points) > MERGE_GROWTH * self._reference_area
        if grown or width > MERGE_GROWTH * self._reference_width:
            return True
        shift = trailing - int(self._reference_contour[:, 1].min())
        overlap = flat_overlap(self._reference_contour, points, shift, int(self.edge_row) - FLAT_MARGIN_PX)
        return overlap < FLAT_OVERLAP_MIN

    def _spills(self, points: np.ndarray) -> bool:
        """Whether this window frame's outline reaches beyond the reference's columns or extent (SPILL_RATIO)."""
        columns = self._reference_contour[:, 0]
        spill = max(columns.min() - points[:, 0].min(), points[:, 0].max() - columns.max())
        if spill > SPILL_RATIO * self._reference_width:
            return True
        extent, own = np.ptp(points[:, 1]), np.ptp(self._reference_contour[:, 1])
        return extent > (1.0 + SPILL_RATIO) * own

    def _finish_line(self) -> ShapeResult:
        frames = self._trace + self._extra
        kept, own = own_frames(frames)
        self._rejected += len(frames) - len(kept)
        line_phi, nearer, gap = interpolate_at(own, self.line_fraction)
        step = self._advance_per_frame() / self._reference.length_px
        if nearer is None or not math.isfinite(line_phi) or is_gap(gap, step):
            line_phi, nearer = extrapolate_at(own, self.line_fraction, step)
        if nearer is None or not math.isfinite(line_phi):
            return self._finish(STATUS_UNSCORED, REASON_LINE_GAP.format(self.line_fraction, self._rejected),
                                line_bounds=bracket_at(own, self.line_fraction))
        reason = REASON_WINDOW_GAP.format(self._window_gap) if self._window_gap else ""
        nearer = kept[nearer]
        return self._finish(STATUS_SCORED, reason, line_phi, self._contours[nearer], frames[nearer].stamp)

    def _advance_per_frame(self) -> float:
        """Rows the fillet moved per camera frame while flat (inf when too few frames tell)."""
        interval = frame_interval([stamp for stamp, _ in self._approach])
        speed = self._speed_px_s()
        return float(speed * interval) if math.isfinite(interval) and math.isfinite(speed) else math.inf

    def _speed_px_s(self) -> float:
        """The fillet's speed along the image rows over its last SPEED_FRAMES flat frames (NaN when too few frames
        tell): its own recent motion, so a belt that changed speed during the approach is measured at its new speed."""
        if len(self._approach) < 2:
            return math.nan
        (t0, r0), (t1, r1) = self._approach[-SPEED_FRAMES:][0], self._approach[-1]
        return (r1 - r0) / (t1 - t0) if t1 > t0 else math.nan

    def overdue(self, stamp: float) -> ShapeResult | None:
        """The unscored result once, by its own speed, this fillet's centroid lies further past the edge at
        ``stamp`` than a late frame may close its window (``GAP_FRAMES`` frames of advance) and no frame closed
        it: its track went unseen or only merged frames came. A frame arriving later would leave it unscored
        anyway (REASON_LATE_CLOSE); deciding now, not when the track ends, gets the verdict to the gate in time.
        The result is stamped with the moment the centroid was due at the edge. A closed window whose measuring
        point no later frame has confirmed (the frames past it merged, or went unseen) is likewise read once, by
        its speed, the fillet lies that far past the point: on the frames it has, as when its track ends. None
        while the window may still close or its point be confirmed, or when the fillet's speed is unknown."""
        if self._phase is _Phase.DONE or self._last_trailing is None:
            return None
        if self._closed:
            past_point = (1.0 - self.line_fraction) * self._reference.length_px  # the measuring point's trailing edge
            return self._finish_line() if self._overdue_px(past_point, stamp) is not None else None
        if self._reference is None and not self._front_past_edge(stamp):
            return None  # the centroid lies behind the front: no outline to measure while the front is short of it
        reference = self._reference or (make_reference(self._flat[-1].points, self.tip_ratio) if self._flat else None)
        if reference is None:
            return None
        overshoot = self._overdue_px(reference.centroid_offset_px, stamp)
        if overshoot is None:
            return None
        due = self._due_at_edge(reference)
        if self._reference is None:
            return self._finish(STATUS_UNSCORED, REASON_OVERDUE_BEFORE_EDGE, stamp=due)
        return self._finish(STATUS_UNSCORED, REASON_OVERDUE_IN_WINDOW.format(overshoot), stamp=due)

    def _overdue_px(self, offset_px: float, stamp: float) -> float | None:
        """How far past the edge, by the fillet's speed, the point ``offset_px`` ahead of its trailing edge lies at
        ``stamp``, when that is further than a late frame may close (``GAP_FRAMES`` frames of advance); None while
        it is not, or when the speed is unknown."""
        overshoot = self.predicted_trailing(stamp) + offset_px - self.edge_row
        late = self._speed_px_s() > 0.0 and overshoot > GAP_FRAMES * self._advance_per_frame()  # False on a NaN speed
        return overshoot if late else None

    def crossing_stamp(self) -> float | None:
        """When the fillet's centroid crossed the edge, or by its speed is due there: its own trailing edge, last
        seen clean, moved at its speed (the part still on the belt rides it while the rest tips); the latest frame's
        stamp before the reference is locked or while the speed is unknown."""
        if self._reference is None or not self._speed_px_s() > 0.0:
            return self._last_stamp
        return self._due_at_edge(self._reference)

    def _due_at_edge(self, reference: ShapeReference) -> float:
        """When ``reference``'s centroid, riding with the fillet's last clean trailing edge, is at the edge."""
        offset = reference.centroid_offset_px
        return self._trailing_stamp + (self.edge_row - offset - self._last_trailing) / self._speed_px_s()

    def _front_past_edge(self, stamp: float) -> bool:
        """Whether the flat fillet's leading edge, moved at its own speed, lies past the edge at ``stamp``."""
        if not self._approach:
            return False
        seen, leading = self._approach[-1]
        return leading + self._speed_px_s() * (stamp - seen) > self.edge_row

    def finish(self) -> ShapeResult | None:
        """The track ended: the unscored result, or None if a result was already produced."""
        if self._phase is _Phase.DONE:
            return None
        if self._closed:
            return self._finish_line()  # scored on the frames around the measuring point, if it was passed
        reason = REASON_LOST_IN_WINDOW if self._trace else REASON_LOST_BEFORE_EDGE
        return self._finish(STATUS_UNSCORED, reason)

    def _score_image(self, image: np.ndarray, stamp: float, overhang: float) -> FrameScore:
        """Φ_t of the image outline's body, clipped like the followed outline's from its own trailing edge."""
        body = clip_body(image, int(image[:, 1].min()), self._image_reference.length_px)
        return self._score(self._image_reference, body, stamp, overhang)

    def _score(self, reference: ShapeReference, body: np.ndarray, stamp: float, overhang: float,
               joined: bool = False) -> FrameScore:
        if len(body) >= 3 and cv2.contourArea(body) > 0.0:
            hu_term, solidity_term = shape_terms(reference, body)
        else:  # a degenerate contour (no area) has no shape to compare: the frame counts, its terms are NaN
            hu_term, solidity_term = math.nan, math.nan
        return FrameScore(stamp, self.w1 * hu_term + self.w2 * solidity_term, hu_term, solidity_term, overhang, joined)

    def _finish(self, status: str, reason: str, line_phi: float = math.nan,
                line_contour: np.ndarray | None = None, line_stamp: float | None = None,
                stamp: float | None = None, line_bounds: tuple[float, float] = (0.0, math.inf)) -> ShapeResult:
        self._phase = _Phase.DONE
        referenced = self._reference is not None
        complete = self._closed and not self._window_gap
        window = self._paper_trace if complete else []
        return ShapeResult(
            status=status,
            reason=reason,
            phi=_nanmax([f.phi for f in window]),
            hu_term=_nanmax([f.hu_term for f in window]),
            solidity_term=_nanmax([f.solidity_term for f in window]),
            frames=len(self._trace),
            stamp=self.crossing_stamp() if stamp is None else stamp,
            aspect_ratio=self._reference.aspect_ratio if referenced else math.nan,
            reference_stamp=self._reference_stamp if referenced else None,
            trace=tuple(self._trace),
            paper_trace=tuple(self._paper_trace),
            line_phi=line_phi,
            line_fraction=self.line_fraction,
            leading_end=leading_end(self._reference_contour) if referenced else "",
            speed_px_s=self._speed_px_s(),
            turn_deg=turn_deg(self._reference_contour) if referenced else math.nan,
            length_px=float(self._reference.length_px) if referenced else math.nan,
            rejected_frames=self._rejected,
            reference_contour=self._reference_contour,
            line_contour=line_contour,
            line_stamp=line_stamp,
            extra_trace=tuple(self._extra),
            window_closed=complete,
            window_gap_s=self._window_gap,
            line_bounds=line_bounds,
        )


def _centroid_column(points: np.ndarray) -> float:
    """Image column of an outline's area centroid (its mean column if it has no area)."""
    m = cv2.moments(points.reshape(-1, 1, 2))
    return m["m10"] / m["m00"] if m["m00"] > 0.0 else float(points[:, 0].mean())


def _nanmax(values: list[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return max(finite) if finite else math.nan
