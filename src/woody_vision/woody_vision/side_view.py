"""Side-view bending metrics of the single-lane baseline: MDM, NMDM and bending energy (paper, Yoon et al.).

Per frame: the fillet's silhouette by background subtraction, its centroid
C_t from image moments and MDM_t = |C_t − roller axle| (px). Per fillet
passage, as the paper's own evaluator does it: NMDM =
min_t MDM_t / (R + h), with R the roller radius and h the vertical distance
from the centroid to the silhouette's topmost row, measured once, in the first
frame whose leading edge reaches the axle column + R; BE = (P² / L) Σ κ² of a
quadratic fit y = a x² + b x + c to the silhouette's skeleton (Zhang–Suen
thinning) in the silhouette's principal-axis frame, with P the contour
perimeter and L the fitted parabola's arc length, kept as the maximum over the
frames from that trigger on (the bend over the roller; flat frames have
κ ≈ 0 and cannot hold the maximum).

Only a whole passage is measured. The tracker finds lost frames by stamp: a
step of more than ``GAP_FRAMES`` frame intervals (the stream's shortest step,
the side camera's rate while a fillet is in view) between any two frames from
a passage's first to the frame that ends it means the minimum, h or BE may lie
in the frames that never came (a grader that fell behind, a network burst).
Such a passage gives a measurement with NMDM, MDM and BE absent (NaN) and the
reason, never the values of the frames that were seen. The step into a
passage's first frame does not count: the side camera runs slower while its
view is empty. Nor does a step its caller planned (``update(..., planned_step=True)``):
the sweeps' side view follows a fillet along the belt at a slower rate on
purpose.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numba
import numpy as np

from woody_vision.frame_checks import is_gap

DEFAULT_DIFF_THRESHOLD = 40
"""Summed |RGB − background| above which a pixel belongs to a fillet."""
DEFAULT_MIN_AREA_PX = 300
DEFAULT_END_FRAMES = 3
"""A passage ends after this many frames without its silhouette."""
_CLOSING_KERNEL = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
_REACH = 4
"""Pixels beyond the raw mask's box that the 5 x 5 blur and closing can still reach."""
MAX_JUMP_PX = 150.0
"""Largest centroid motion between frames still taken as the same fillet (a falling fillet is fast)."""


@dataclass(frozen=True)
class SideMeasurement:
    """The side-view metrics of one fillet passage."""

    nmdm: float
    mdm_min_px: float
    be: float
    h_px: float
    stamp_of_min: float
    first_stamp: float
    last_stamp: float
    frames: int
    reason: str = ""
    """Why NMDM, MDM and BE are absent (NaN): frames of the passage were lost; '' for a whole passage."""

    @property
    def complete(self) -> bool:
        return not self.reason


REASON_SIDE_GAP = "side view absent: frames lost in the passage ({:.3f} s between frames, {:.3f} s expected)"


def silhouette(rgb: np.ndarray, background: np.ndarray, threshold: int = DEFAULT_DIFF_THRESHOLD) -> np.ndarray:
    """uint8 mask (255 = fillet) of pixels that differ from the empty-scene background.

    Smoothed as the seed's evaluator smooths its mask (a 5 x 5 blur and a
    closing), so the outline is not stair-stepped: steps give the skeleton
    spurs and the parabola fit a curvature the fillet does not have (bending
    energy of a folded k = 0 fillet 265-400 instead of 27-30). The blur acts on
    the thresholded mask and is cut at one half, which leaves a straight
    edge where it was (blurring the difference image before a low threshold
    would move every edge out by a pixel, and h and NMDM with it). Worked on
    the differing pixels' box only: nothing outside it (plus the blur's and
    the closing's reach) can change.
    """
    raw = difference_mask(rgb, background, threshold)
    mask = np.zeros_like(raw)
    x, y, w, h = cv2.boundingRect(raw)
    if w == 0:
        return mask
    x0, y0 = max(x - _REACH, 0), max(y - _REACH, 0)
    x1, y1 = min(x + w + _REACH, raw.shape[1]), min(y + h + _REACH, raw.shape[0])
    smooth = cv2.compare(cv2.GaussianBlur(raw[y0:y1, x0:x1], (5, 5), 0), 127.0, cv2.CMP_GT)
    mask[y0:y1, x0:x1] = cv2.morphologyEx(smooth, cv2.MORPH_CLOSE, _CLOSING_KERNEL)
    return mask


def difference_mask(rgb: np.ndarray, background: np.ndarray, threshold: int) -> np.ndarray:
    """uint8 mask, 255 where the absolute differences of two (H, W, 3) images summed over R, G and B exceed
    ``threshold``.

    One compiled pass (0.5 ms at 960 x 696, against 1.3 ms for OpenCV's absdiff and a channel-summing
    transform); it runs on every side frame.
    """
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape != background.shape:
        raise ValueError(f"difference_mask: two (H, W, 3) images expected, got {rgb.shape} and {background.shape}")
    mask = np.empty(rgb.shape[:2], np.uint8)
    _difference_mask(np.ascontiguousarray(rgb).reshape(-1), np.ascontiguousarray(background).reshape(-1),
                     min(max(int(threshold), 0), 65535), mask.reshape(-1))
    return mask


@numba.njit(cache=True, nogil=True)
def _difference_mask(rgb: np.ndarray, background: np.ndarray, threshold: int, mask: np.ndarray) -> None:
    limit = np.uint16(threshold)
    for i in range(mask.shape[0]):
        total = np.uint16(0)
        for c in range(3):  # |a - b| in uint8, summed in uint16, no branch: the loop vectorises
            a, b = rgb[3 * i + c], background[3 * i + c]
            total += np.uint16(max(a, b) - min(a, b))
        mask[i] = np.uint8(255) if total > limit else np.uint8(0)


def mdm(centroid: tuple[float, float], axle: tuple[float, float]) -> float:
    """Distance (px) from the silhouette centroid to the roller axle."""
    return math.hypot(centroid[0] - axle[0], centroid[1] - axle[1])


def nmdm(min_mdm_px: float, roller_radius_px: float, h_px: float) -> float:
    """min MDM normalised by roller radius plus the centroid-to-top distance."""
    return min_mdm_px / (roller_radius_px + h_px)


def _zhang_suen_tables() -> tuple[np.ndarray, np.ndarray]:
    """Per sub-iteration, which 8-neighbourhood codes remove the centre pixel (Zhang & Suen 1984).

    Bit i of a code is neighbour P(i + 2), clockwise from north (P2 .. P9).
    """
    tables = np.zeros((2, 256), bool)
    for code in range(256):
        p = [(code >> i) & 1 for i in range(8)]  # P2..P9
        neighbours = sum(p)
        transitions = sum(p[i] == 0 and p[(i + 1) % 8] == 1 for i in range(8))
        p2, p4, p6, p8 = p[0], p[2], p[4], p[6]
        base = 2 <= neighbours <= 6 and transitions == 1
        tables[0, code] = base and p2 * p4 * p6 == 0 and p4 * p6 * p8 == 0
        tables[1, code] = base and p2 * p4 * p8 == 0 and p2 * p6 * p8 == 0
    return tables


_ZS_TABLES = _zhang_suen_tables()


def warm_up() -> None:
    """Compile the side view's kernels (or load them from numba's cache) before the first frame: a node that
    compiled on its first passage would miss frames of it and measure a partial passage."""
    frame = np.zeros((8, 8, 3), np.uint8)
    difference_mask(frame, frame, 30)
    zhang_suen_thinning(np.ones((5, 5), np.uint8))


def zhang_suen_thinning(mask: np.ndarray) -> np.ndarray:
    """One-pixel-wide skeleton (bool) of a binary mask, by Zhang–Suen thinning with a neighbourhood lookup."""
    img = np.pad((np.asarray(mask) > 0).astype(np.uint8), 1)
    _thin_in_place(img, _ZS_TABLES)
    return img[1:-1, 1:-1].astype(bool)


@numba.njit(cache=True, nogil=True)
def _thin_in_place(img: np.ndarray, tables: np.ndarray) -> None:
    """Zhang–Suen on a zero-bordered 0/1 image, visiting only the border of what is left.

    Each sub-iteration decides on the image as it was when it began (the
    parallel rule), then removes. A pixel whose eight neighbours are all set
    can never be removed (it needs 2..6 of them), so only the frontier is
    tested: set pixels with an unset neighbour, which grows by the set
    neighbours of every removed pixel. Stops after a round (both tables) that
    removed nothing, as the textbook loop does.
    """
    h, w = img.shape
    seen = np.zeros((h, w), np.int32)
    frontier = np.empty((h * w, 2), np.int32)
    n = 0
    for r in range(1, h - 1):
        for c in range(1, w - 1):
            if img[r, c] and (img[r - 1, c - 1] == 0 or img[r - 1, c] == 0 or img[r - 1, c + 1] == 0
                              or img[r, c - 1] == 0 or img[r, c + 1] == 0 or img[r + 1, c - 1] == 0
                              or img[r + 1, c] == 0 or img[r + 1, c + 1] == 0):
                frontier[n, 0], frontier[n, 1] = r, c
                n += 1
    removed = np.empty((h * w, 2), np.int32)
    epoch = 0
    while True:
        changed = False
        for t in range(2):
            m = 0
            for i in range(n):
                r, c = frontier[i, 0], frontier[i, 1]
                code = (img[r - 1, c] | (img[r - 1, c + 1] << 1) | (img[r, c + 1] << 2) | (img[r + 1, c + 1] << 3)
                        | (img[r + 1, c] << 4) | (img[r + 1, c - 1] << 5) | (img[r, c - 1] << 6)
                        | (img[r - 1, c - 1] << 7))
                if tables[t, code]:
                    removed[m, 0], removed[m, 1] = r, c
                    m += 1
            if m == 0:
                continue
            changed = True
            for i in range(m):
                img[removed[i, 0], removed[i, 1]] = 0
            epoch += 1
            kept = 0
            for i in range(n):  # still set: still on the frontier
                r, c = frontier[i, 0], frontier[i, 1]
                if img[r, c]:
                    seen[r, c] = epoch
                    frontier[kept, 0], frontier[kept, 1] = r, c
                    kept += 1
            for i in range(m):  # the set neighbours of what went are frontier now
                for dr in range(-1, 2):
                    for dc in range(-1, 2):
                        r, c = removed[i, 0] + dr, removed[i, 1] + dc
                        if img[r, c] and seen[r, c] != epoch:
                            seen[r, c] = epoch
                            frontier[kept, 0], frontier[kept, 1] = r, c
                            kept += 1
            n = kept
        if not changed:
            return


def principal_axis_points(mask: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(n, 2) points (x, y) turned into the mask's principal-axis frame (x along its long axis)."""
    m = cv2.moments(mask, binaryImage=True)
    angle = 0.5 * math.atan2(2.0 * m["mu11"], m["mu20"] - m["mu02"])
    c, s = math.cos(angle), math.sin(angle)
    centred = points - np.array([m["m10"] / m["m00"], m["m01"] / m["m00"]])
    return centred @ np.array([[c, -s], [s, c]])


def bending_energy(mask: np.ndarray) -> float:
    """BE = (P² / L) Σ κ² along a quadratic fit to the skeleton of a silhouette mask (the seed's procedure).

    The skeleton is turned into the silhouette's principal-axis frame and
    fitted with y = a x² + b x + c; κ is the fit's curvature at every skeleton
    pixel, P the outer contour's perimeter and L the fitted parabola's arc
    length over the skeleton's extent.
    """
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        return math.nan
    perimeter = cv2.arcLength(max(contours, key=cv2.contourArea), True)
    ys, xs = np.nonzero(zhang_suen_thinning(mask))
    if xs.size < 3:
        return math.nan
    pts = principal_axis_points(mask, np.column_stack([xs, ys]).astype(float))
    if np.ptp(pts[:, 0]) == 0:
        return math.nan
    a, b, _ = np.polyfit(pts[:, 0], pts[:, 1], 2)
    kappa = 2.0 * abs(a) / (1.0 + (2.0 * a * pts[:, 0] + b) ** 2) ** 1.5
    grid = np.linspace(pts[:, 0].min(), pts[:, 0].max(), 256)
    length = float(np.trapezoid(np.sqrt(1.0 + (2.0 * a * grid + b) ** 2), grid))
    return float(perimeter**2 / length * np.sum(kappa**2))


@dataclass
class _Passage:
    first_stamp: float
    centroid: tuple[float, float]
    last_stamp: float = 0.0
    frames: int = 0
    unseen: int = 0
    h_px: float = math.nan
    min_mdm: float = math.inf
    stamp_of_min: float = 0.0
    be: float = math.nan
    approached: bool = False
    """Seen with its leading edge short of the h trigger, so the trigger frame is a real crossing."""
    longest_step: float = 0.0
    """The longest step between frames (s) from the passage's first frame to its last."""


class SidePassageTracker:
    """Follows fillets through the side camera's view and measures each one once it has passed."""

    def __init__(self, axle_px: tuple[float, float], roller_radius_px: float, background: np.ndarray | None = None,
                 diff_threshold: int = DEFAULT_DIFF_THRESHOLD, min_area_px: int = DEFAULT_MIN_AREA_PX,
                 end_frames: int = DEFAULT_END_FRAMES) -> None:
        if roller_radius_px <= 0:
            raise ValueError(f"roller_radius_px must be > 0, got {roller_radius_px}")
        if min_area_px < 1 or end_frames < 1:
            raise ValueError("min_area_px and end_frames must be >= 1")
        self.axle = (float(axle_px[0]), float(axle_px[1]))
        self.radius = float(roller_radius_px)
        self.diff_threshold = diff_threshold
        self.min_area_px = min_area_px
        self.end_frames = end_frames
        self._given_background = background
        self.background = background
        self._passages: list[_Passage] = []
        self._last_stamp: float | None = None
        self.interval = math.inf
        """The stream's frame interval: its shortest step between frames so far (s)."""

    def reset(self) -> None:
        """Forget passages and the stream's stamps, and relearn the background from the next frame (unless one
        was given)."""
        self.background = self._given_background
        self._passages = []
        self._last_stamp = None
        self.interval = math.inf

    def update(self, rgb: np.ndarray, stamp: float, planned_step: bool = False) -> list[SideMeasurement]:
        """Feed one side frame; returns the measurements of passages that ended with it. ``planned_step``: the
        step from the previous frame is the caller's own choice of rate, not frames lost."""
        self._note_step(stamp, planned_step)
        if self.background is None or self.background.shape != rgb.shape:
            self.background = rgb.copy()
            self._passages = []
            return []
        count, labels, stats, centroids, origin = _components(silhouette(rgb, self.background, self.diff_threshold))
        blobs = [i for i in range(1, count) if stats[i, cv2.CC_STAT_AREA] >= self.min_area_px]
        unmatched = set(blobs)
        for passage in sorted(self._passages, key=lambda p: -p.centroid[0]):
            best = min(unmatched, key=lambda i: _distance(centroids[i], passage.centroid), default=None)
            if best is None or _distance(centroids[best], passage.centroid) > MAX_JUMP_PX:
                passage.unseen += 1
                continue
            unmatched.discard(best)
            self._observe(passage, _own_mask(labels, stats[best], best, origin), stats[best], centroids[best], stamp)
        for i in unmatched:
            passage = _Passage(first_stamp=stamp, centroid=(float(centroids[i][0]), float(centroids[i][1])))
            self._observe(passage, _own_mask(labels, stats[i], i, origin), stats[i], centroids[i], stamp)
            self._passages.append(passage)
        done = [p for p in self._passages if p.unseen >= self.end_frames]
        self._passages = [p for p in self._passages if p.unseen < self.end_frames]
        return [m for m in (self._measure(p) for p in done) if m is not None]

    def _note_step(self, stamp: float, planned: bool) -> None:
        """Learn the frame interval and charge the step since the last frame (unless planned) to every passage
        in progress."""
        step = stamp - self._last_stamp if self._last_stamp is not None else 0.0
        self._last_stamp = stamp
        if step > 0.0:
            self.interval = min(self.interval, step)
        if planned:
            return
        for passage in self._passages:
            passage.longest_step = max(passage.longest_step, step)

    def _observe(self, passage: _Passage, own: np.ndarray, stat: np.ndarray, centroid: np.ndarray,
                 stamp: float) -> None:
        """``own``: the blob's pixels within its bounding box ``stat`` (frame coordinates)."""
        u, v = float(centroid[0]), float(centroid[1])
        passage.centroid, passage.last_stamp, passage.unseen = (u, v), stamp, 0
        passage.frames += 1
        x, y, w, h = (int(s) for s in stat[:4])
        reached = x + w - 1 >= self.axle[0] + self.radius  # the seed's h trigger: leading edge at axle + R
        if reached and passage.approached and math.isnan(passage.h_px):
            passage.h_px = v - y
        passage.approached |= not reached
        distance = mdm((u, v), self.axle)
        if distance < passage.min_mdm:
            passage.min_mdm, passage.stamp_of_min = distance, stamp
        if math.isfinite(passage.h_px):
            be = bending_energy(np.pad(own.astype(np.uint8) * 255, 1))
            passage.be = max(passage.be, be) if math.isfinite(passage.be) else be

    def _measure(self, passage: _Passage) -> SideMeasurement | None:
        if not math.isfinite(passage.h_px) or passage.h_px <= 0.0:
            return None  # never seen reaching the roller (entered mid-fall, or a speck): no reliable h
        if is_gap(passage.longest_step, self.interval):
            nan = math.nan
            return SideMeasurement(nmdm=nan, mdm_min_px=nan, be=nan, h_px=nan, stamp_of_min=nan,
                                   first_stamp=passage.first_stamp, last_stamp=passage.last_stamp,
                                   frames=passage.frames,
                                   reason=REASON_SIDE_GAP.format(passage.longest_step, self.interval))
        return SideMeasurement(nmdm=nmdm(passage.min_mdm, self.radius, passage.h_px), mdm_min_px=passage.min_mdm,
                               be=passage.be, h_px=passage.h_px, stamp_of_min=passage.stamp_of_min,
                               first_stamp=passage.first_stamp, last_stamp=passage.last_stamp, frames=passage.frames)


def _components(mask: np.ndarray) -> tuple[int, np.ndarray | None, np.ndarray, np.ndarray, tuple[int, int]]:
    """Connected components of the mask, labelled within the bounding box of its pixels only (the fillet
    covers a small part of the frame): count, labels of that box, stats and centroids in frame coordinates,
    and the box origin."""
    x, y, w, h = cv2.boundingRect(mask)
    if w == 0 or h == 0:
        return 1, None, np.zeros((1, 5), np.int32), np.zeros((1, 2)), (0, 0)
    # Grana's labelling: same components as the default, ~3x faster with stats on one thread.
    count, labels, stats, centroids = cv2.connectedComponentsWithStatsWithAlgorithm(
        np.ascontiguousarray(mask[y:y + h, x:x + w]), 8, cv2.CV_32S, cv2.CCL_GRANA)
    stats[:, cv2.CC_STAT_LEFT] += x
    stats[:, cv2.CC_STAT_TOP] += y
    return count, labels, stats, centroids + (x, y), (x, y)


def _own_mask(labels: np.ndarray, stat: np.ndarray, label: int, origin: tuple[int, int]) -> np.ndarray:
    """Boolean mask of one component within its bounding box."""
    x, y, w, h = (int(s) for s in stat[:4])
    x, y = x - origin[0], y - origin[1]
    return labels[y:y + h, x:x + w] == label


def _distance(a, b) -> float:
    return math.hypot(float(a[0]) - float(b[0]), float(a[1]) - float(b[1]))
