"""Depth-based fillet segmentation for the top camera (paper: background subtraction + watershed).

Pipeline per frame: height map = learned empty-belt depth − depth; mask where the
height exceeds a few millimetres; morphological opening; connected components;
and only for components that look like several fillets (low solidity), a
watershed on the distance transform seeded from its cores (or, for fillets
touching side by side along a long contact, which leave a single core, from the
two halves of a cut between the contact's end notches), so fillets touching in
a lane or across lanes come apart. A component wider across the flow than
one fillet can be (``split_width_px``) may be two fillets lying side by side
along their whole length, solid as one and without notches: it is split by a
watershed on the height map from its thick cores, since the touching rims are
a few millimetres high and the fillets' middles centimetres. A component
longer along the flow than one fillet can be (``split_length_px``) is two
fillets touching end to end, split at their necks however solid it looks.
Blobs under ``min_area_px`` are dropped.

Everything per pixel is OpenCV/numpy; the Python loop runs over components
(a handful per frame) and works on each component's bounding-box ROI.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numba
import numpy as np

from woody_common.line import MAX_FILLET_AREA_M2, MAX_FILLET_LENGTH_M, MAX_FILLET_WIDTH_M
from woody_vision.flood import flood

DEFAULT_HEIGHT_THRESHOLD_M = 0.0005
"""Pixels rising more than this above the learned background belong to a fillet. Kept below the thickness of a
fillet's thin rim: on the belt, rim thinner than the threshold is not segmented, but past the roller edge the
background is the floor and the same rim is, so a high threshold makes the outline grow as the fillet crosses
the edge whether it bends or not (5 mm gave stiff real meshes a k-independent Φ of about 2; 2 mm about 1, and
the stiff class a line score 1.8 times its 0.5 mm one). The ideal camera has no depth noise to stay above; a
real one does (REAL_CAMERA_FILTERS)."""
DEFAULT_MIN_AREA_PX = 500
"""Blobs smaller than this are noise or slivers, never a fillet (paper: 500 px)."""
REAL_CAMERA_FILTERS = {"fill_invalid_px": 4, "median_px": 5, "blur_px": 1.0, "height_threshold_m": 0.005,
                       "color_threshold": 20.0, "color_search_px": 8}
"""The hole filling and smoothing recommended for a real (or modelled) camera (docs/real-camera.md); the
height threshold goes back to 5 mm, since a lower cut sits inside a real sensor's ~2 mm depth noise, and the
outline comes from the registered colour image (20 levels: several times a camera's colour noise, well under
the fillet-to-belt contrast; docs/sensors.md, "Robustness")."""


@dataclass(frozen=True)
class Blob:
    """One segmented fillet in image coordinates (u = column, v = row)."""

    contour: np.ndarray
    """(K, 2) int32 outer contour, (u, v) per point."""
    centroid: tuple[float, float]
    """(u, v) centroid of the blob's pixels."""
    area_px: int
    bbox: tuple[int, int, int, int]
    """(u, v, width, height) of the bounding box."""
    mean_height_m: float


HEIGHT_CORE_RATIO = 0.75
"""The first cut of a wide blob's relief (× its highest pixel), and by default the only one."""


@dataclass(frozen=True)
class SegmentationParams:
    """Tuning of :func:`segment_height_map`; defaults follow the paper's top-down setup."""

    height_threshold_m: float = DEFAULT_HEIGHT_THRESHOLD_M
    min_area_px: int = DEFAULT_MIN_AREA_PX
    open_kernel_px: int = 5
    """Elliptic opening kernel that removes specks and thin contact bridges (0 disables)."""
    split_solidity: float = 0.93
    """Components less solid (area / hull area) than this are checked for several fillets."""
    core_ratio: float = 0.5
    """Watershed markers: the component's pixels farther than this × its max distance from the border."""
    height_core_ratio: float = HEIGHT_CORE_RATIO
    """Markers of a wide component split by height: its pixels higher than this × its highest pixel (two
    fillets' middles stay apart above three quarters of the thicker one's height, also when they overlap)."""
    height_core_floor: float = HEIGHT_CORE_RATIO
    """The lowest cut tried for those markers when the first finds one fillet only (in steps of 0.05; the
    default tries one cut): a fillet much thinner than its neighbour rises above the saddle between them only
    below three quarters of the thicker one's height. Lower (0.5) splits more of the fillets that merge side by
    side at the edge, so fewer are unscored, but the boundary it draws is a few pixels off and more woody
    fillets pass (docs/results.md)."""
    split_width_px: float = 0.0
    """Components wider than this across the flow (columns) are checked for fillets side by side by height
    (0 = off; the segmenter sets it from the camera and ``max_fillet_width_m``)."""
    split_length_px: float = 0.0
    """Components longer than this along the flow (rows) are two fillets touching end to end, however solid they
    look, and are split at their necks like a non-convex one (0 = off; the segmenter sets it from the camera and
    ``max_fillet_length_m``)."""
    split_area_px: float = 0.0
    """Components wider than ``split_width_px`` that cover more pixels than this are surely fillets side by side
    (one turned fillet lies as wide, but covers no more than its own area): their relief is cut down to
    LONG_CORE_FLOOR, like a component too long for one fillet, not only to ``height_core_floor`` (0 = off; the
    segmenter sets it from the camera and ``max_fillet_area_m2``)."""
    fill_invalid_px: int = 0
    """Pixels without a depth measurement take the mean height of the valid ones within this radius (0 = off):
    a real camera's holes at a fillet's border would otherwise notch its contour."""
    median_px: int = 0
    """Median filter of the height map (0 = off, 3 or 5): a noisy camera's depth would otherwise fray contours."""
    blur_px: float = 0.0
    """Gaussian σ (px) smoothing the height map after the median (0 = off): frayed contours lose solidity and
    would be split as if they were two touching fillets."""
    color_threshold: float = 0.0
    """Outline from the registered colour image (0 = off): near the depth mask, a pixel is fillet when its colour
    differs from the empty belt's by more than this (8-bit levels, RGB distance). Depth noise of a few mm moves a
    thin rim's contour by pixels; a camera's colour noise of a few levels does not."""
    color_search_px: int = 8
    """Colour refines the outline only within this distance (px) of the depth mask: depth decides where a fillet
    is, so a stain, glare or shadow elsewhere never becomes one."""
    split_by_tracks: bool = True
    """Split a blob holding the predicted outlines of several tracked fillets side by side into them
    (:func:`_split_by_priors`): fillets that merge with a neighbour as they tip over the edge are scored instead
    of unscored. The split boundary of two touching fillets is a few pixels off; the grader rejects a window frame
    a neighbour's piece reaches into, so no woody fillet passed on it (docs/results.md, "Splitting merged fillets
    by their tracks")."""

    def for_camera(self, k, camera_height_m: float, max_width_m: float = MAX_FILLET_WIDTH_M,
                   max_length_m: float = MAX_FILLET_LENGTH_M,
                   max_area_m2: float = MAX_FILLET_AREA_M2) -> SegmentationParams:
        """These parameters with ``split_width_px``, ``split_length_px`` and ``split_area_px`` for a camera
        (row-major K) this high over the belt: the widest, the longest and the largest a single fillet lies, in its
        pixels."""
        across, along = k[0] / camera_height_m, k[4] / camera_height_m
        return dataclasses.replace(self, split_width_px=max_width_m * across, split_length_px=max_length_m * along,
                                   split_area_px=max_area_m2 * across * along)

    def __post_init__(self) -> None:
        if not self.height_threshold_m > 0.0:
            raise ValueError(f"height_threshold_m must be > 0, got {self.height_threshold_m}")
        if self.min_area_px < 1:
            raise ValueError(f"min_area_px must be >= 1, got {self.min_area_px}")
        if self.open_kernel_px < 0:
            raise ValueError(f"open_kernel_px must be >= 0, got {self.open_kernel_px}")
        if not 0.0 < self.split_solidity <= 1.0:
            raise ValueError(f"split_solidity must be in (0, 1], got {self.split_solidity}")
        if not (0.0 < self.core_ratio < 1.0 and 0.0 < self.height_core_floor <= self.height_core_ratio < 1.0):
            raise ValueError(f"core_ratio must be in (0, 1) and 0 < height_core_floor <= height_core_ratio < 1, got "
                             f"{self.core_ratio}, {self.height_core_floor}, {self.height_core_ratio}")
        if not (self.split_width_px >= 0.0 and self.split_length_px >= 0.0 and self.split_area_px >= 0.0):
            raise ValueError(f"split_width_px, split_length_px and split_area_px must be >= 0, got "
                             f"{self.split_width_px}, {self.split_length_px}, {self.split_area_px}")
        if self.color_threshold < 0 or self.color_search_px < 0:
            raise ValueError(f"color_threshold and color_search_px must be >= 0, got {self.color_threshold}, "
                             f"{self.color_search_px}")
        if self.fill_invalid_px < 0 or self.median_px not in (0, 3, 5) or self.blur_px < 0:
            raise ValueError(f"fill_invalid_px and blur_px must be >= 0 and median_px 0, 3 or 5, got "
                             f"{self.fill_invalid_px}, {self.blur_px}, {self.median_px}")


class BackgroundModel:
    """Empty-belt depth (and colour), the per-pixel median of the first ``frames_needed`` frames fed to it.

    Non-finite and non-positive depths (no return) are ignored in the median; a pixel never seen
    stays NaN and therefore never rises above the belt in :func:`height_map`. The colour background
    is the median of the colour frames that came with those frames (None if none did).
    Call :meth:`reset` to relearn, e.g. after the camera or belt moved.
    """

    def __init__(self, frames_needed: int = 1) -> None:
        if frames_needed < 1:
            raise ValueError(f"frames_needed must be >= 1, got {frames_needed}")
        self.frames_needed = frames_needed
        self.reset()

    @property
    def ready(self) -> bool:
        """True once the background has been learned."""
        return self._depth is not None

    @property
    def depth(self) -> np.ndarray:
        """The learned background depth (float32, metres, NaN where never measured)."""
        if self._depth is None:
            raise RuntimeError("background not learned yet: feed frames with add() until ready")
        return self._depth

    @property
    def color(self) -> np.ndarray | None:
        """The learned background colour (float32 (H, W, 3)), None until learned or when no frame had colour."""
        return self._color

    def add(self, depth: np.ndarray, color: np.ndarray | None = None) -> bool:
        """Feed one empty-belt depth frame (and its registered colour); returns :attr:`ready`.

        Frames after learning are ignored."""
        if self._depth is not None:
            return True
        frame = np.asarray(depth, dtype=np.float32)
        if self._frames and frame.shape != self._frames[0].shape:
            raise ValueError(f"depth shape changed from {self._frames[0].shape} to {frame.shape}")
        if color is not None and np.shape(color) != frame.shape + (3,):
            raise ValueError(f"colour shape {np.shape(color)} does not match depth {frame.shape}")
        with np.errstate(invalid="ignore"):
            frame = np.where(np.isfinite(frame) & (frame > 0.0), frame, np.float32(np.nan))
        self._frames.append(frame)
        if color is not None:
            self._colors.append(np.asarray(color, dtype=np.float32))
        if len(self._frames) >= self.frames_needed:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN pixels stay NaN on purpose
                self._depth = np.nanmedian(np.stack(self._frames), axis=0).astype(np.float32)
            self._color = np.median(np.stack(self._colors), axis=0).astype(np.float32) if self._colors else None
            self._frames, self._colors = [], []
        return self.ready

    def reset(self) -> None:
        """Forget the background so the next frames relearn it."""
        self._frames: list[np.ndarray] = []
        self._colors: list[np.ndarray] = []
        self._depth: np.ndarray | None = None
        self._color: np.ndarray | None = None


def height_map(depth: np.ndarray, background: np.ndarray) -> np.ndarray:
    """Height above the learned background in metres (float32); NaN/inf anywhere or depth <= 0 (no return) become 0.

    One compiled pass (0.1 ms per 672 x 376 frame instead of numpy's 0.33 ms, the same values)."""
    return _height_map(np.asarray(depth, np.float32), np.asarray(background, np.float32))


@numba.njit(cache=True, nogil=True)
def _height_map(depth: np.ndarray, background: np.ndarray) -> np.ndarray:
    height = np.empty(depth.shape, np.float32)
    for r in range(depth.shape[0]):
        for c in range(depth.shape[1]):
            d = depth[r, c]
            h = background[r, c] - d
            height[r, c] = h if math.isfinite(h) and d > 0.0 else np.float32(0.0)
    return height


def segment_depth(
    depth: np.ndarray, background: np.ndarray, params: SegmentationParams = SegmentationParams(),
    color: np.ndarray | None = None, color_background: np.ndarray | None = None,
    priors: Sequence[np.ndarray] = (),
) -> list[Blob]:
    """Segment the fillets in a depth frame against a background depth.

    With ``params.color_threshold`` set and a registered colour frame and colour background given,
    the outline near the depth mask comes from the colour (:func:`refine_with_color`). ``priors`` are the
    outlines where the tracked fillets should lie in this frame (:func:`_split_by_priors`)."""
    height = height_map(depth, background)
    if params.fill_invalid_px:
        with np.errstate(invalid="ignore"):
            valid = np.isfinite(depth) & (depth > 0.0) & np.isfinite(background)
        height = fill_invalid(height, valid, params.fill_invalid_px)
    if params.median_px:
        height = cv2.medianBlur(height, params.median_px)
    if params.blur_px:
        height = cv2.GaussianBlur(height, (0, 0), params.blur_px)
    mask = cv2.compare(height, params.height_threshold_m, cv2.CMP_GT) if height.size else None
    if mask is not None and params.color_threshold and color is not None and color_background is not None:
        mask = refine_with_color(mask, color, color_background, params)
    return segment_mask(mask, height, params, priors)


def refine_with_color(depth_mask: np.ndarray, color: np.ndarray, color_background: np.ndarray,
                      params: SegmentationParams) -> np.ndarray:
    """Fillet pixels by colour change from the empty belt, kept only within ``color_search_px`` of the depth mask.

    Depth finds the fillets; the colour, whose noise is a few levels against a fillet-to-belt contrast of tens,
    draws their outline, which depth noise at a thin rim would fray."""
    if np.shape(color) != depth_mask.shape + (3,) or np.shape(color_background) != np.shape(color):
        raise ValueError(f"colour {np.shape(color)} and its background {np.shape(color_background)} must be "
                         f"registered to the depth image {depth_mask.shape}")
    distance = np.linalg.norm(np.asarray(color, np.float32) - color_background, axis=2).astype(np.float32)
    changed = cv2.compare(distance, params.color_threshold, cv2.CMP_GT)
    size = 2 * params.color_search_px + 1
    near = cv2.dilate(depth_mask, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size)))
    return cv2.bitwise_and(changed, near)


def fill_invalid(height: np.ndarray, valid: np.ndarray, radius_px: int) -> np.ndarray:
    """Invalid pixels get the mean height of the valid pixels in a (2r+1)² box around them (0 if there are none)."""
    size = (2 * radius_px + 1, 2 * radius_px + 1)
    weights = valid.astype(np.float32)
    total = cv2.boxFilter(height * weights, -1, size, normalize=False, borderType=cv2.BORDER_CONSTANT)
    count = cv2.boxFilter(weights, -1, size, normalize=False, borderType=cv2.BORDER_CONSTANT)
    mean = np.divide(total, count, out=np.zeros_like(total), where=count > 0)
    return np.where(valid, height, mean).astype(np.float32)


def warm_up() -> None:
    """Compile the segmentation's kernels (height map, watershed flood) or load them from numba's cache before the
    first frame, so a node never falls behind its camera while it compiles."""
    rows, cols = np.mgrid[0:40, 0:70]
    discs = ((cols - 20) ** 2 + (rows - 20) ** 2 < 225) | ((cols - 46) ** 2 + (rows - 20) ** 2 < 225)
    depth = np.where(discs, 0.98, 1.0).astype(np.float32)
    segment_depth(depth, np.ones_like(depth), SegmentationParams(min_area_px=10, open_kernel_px=0))


def segment_height_map(height: np.ndarray, params: SegmentationParams = SegmentationParams()) -> list[Blob]:
    """Split a height map into fillet blobs, sorted by centroid row then column."""
    mask = cv2.compare(height, params.height_threshold_m, cv2.CMP_GT) if height.size else None
    return segment_mask(mask, height, params)


def segment_mask(mask: np.ndarray | None, height: np.ndarray, params: SegmentationParams,
                 priors: Sequence[np.ndarray] = ()) -> list[Blob]:
    """Split a fillet mask (uint8, 255 = fillet; None for a 0-pixel frame) into blobs with heights from ``height``,
    and blobs holding several of the ``priors`` (outlines where tracked fillets should lie) into those fillets."""
    if mask is None:  # a 0-pixel frame has no fillets (OpenCV would assert on it)
        return []
    # Fillets cover about a quarter of the frame's bounding box of fillet pixels, so the opening and the labelling
    # run on that box (with a margin the opening needs), which gives the same components.
    margin = params.open_kernel_px // 2 + 1
    bx, by, bw, bh = cv2.boundingRect(mask)
    if bw == 0:
        return []
    rows, cols = mask.shape
    cx0, cy0 = max(bx - margin, 0), max(by - margin, 0)
    cx1, cy1 = min(bx + bw + margin, cols), min(by + bh + margin, rows)
    crop = mask[cy0:cy1, cx0:cx1]
    if params.open_kernel_px > 1:
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (params.open_kernel_px, params.open_kernel_px))
        crop = cv2.morphologyEx(crop, cv2.MORPH_OPEN, kernel)
    # Grana's block-based labelling: same components, ~3x faster with stats than the default on one thread.
    count, labels, stats, _ = cv2.connectedComponentsWithStatsWithAlgorithm(crop, 8, cv2.CV_32S, cv2.CCL_GRANA)
    height = np.asarray(height, np.float32)[cy0:cy1, cx0:cx1]
    blobs: list[Blob] = []
    rows, cols = crop.shape
    for label in range(1, count):
        x, y, w, h, area = (int(s) for s in stats[label])
        if area < params.min_area_px:
            continue
        # ROI with a 1-pixel empty frame so contours and watershed never touch the ROI border.
        x0, y0 = max(x - 1, 0), max(y - 1, 0)
        x1, y1 = min(x + w + 1, cols), min(y + h + 1, rows)
        component = _pad(cv2.compare(labels[y0:y1, x0:x1], label, cv2.CMP_EQ))
        origin = (cx0 + x0 - 1, cy0 + y0 - 1)
        height_roi = _pad(height[y0:y1, x0:x1])
        parts = _split_component(component, height_roi, params)
        if params.split_by_tracks:
            parts = _split_by_tracks(parts, priors, origin, params)
        for mask_roi, contour in parts:
            blob = _make_blob(mask_roi, contour, height_roi, origin, params.min_area_px)
            if blob is not None:
                blobs.append(blob)
    blobs.sort(key=lambda b: (b.centroid[1], b.centroid[0]))
    return blobs


def _pad(roi: np.ndarray) -> np.ndarray:
    """The ROI inside a 1-pixel frame of zeros (one OpenCV call; 3x faster than numpy's zeros and assignment)."""
    return cv2.copyMakeBorder(roi, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)


def _split_component(component: np.ndarray, height: np.ndarray,
                     params: SegmentationParams) -> list[tuple[np.ndarray, np.ndarray | None]]:
    """Masks of the fillets in one connected component (itself if it looks like one fillet), each with its
    outline when already known (None: to be traced)."""
    contour = _largest_contour(component)
    parts = (None if _solid(contour, params) else _split_by_distance(component, contour, params)) \
        or [(component, contour)]
    wide = [piece for part in parts for piece in _split_if_wide(part, height, params)]
    return [piece for part in wide for piece in _split_if_long(part, height, params)]


def _split_if_wide(part: tuple[np.ndarray, np.ndarray | None], height: np.ndarray,
                   params: SegmentationParams) -> list[tuple[np.ndarray, np.ndarray | None]]:
    """The part, or the fillets side by side in it when it is wider than one fillet can be (cut deeper when it also
    covers more than one fillet can)."""
    mask = part[0]
    if not 0.0 < params.split_width_px < cv2.boundingRect(mask)[2]:
        return [part]
    surely = 0.0 < params.split_area_px < cv2.countNonZero(mask)
    return _split_by_height(mask, height, params, floor=LONG_CORE_FLOOR if surely else None) or [part]


def _split_if_long(part: tuple[np.ndarray, np.ndarray | None], height: np.ndarray,
                   params: SegmentationParams) -> list[tuple[np.ndarray, np.ndarray | None]]:
    """The part, or the fillets end to end in it when it is longer along the flow than one fillet can be: split
    by height from its thick middles one behind the other (two fillets touching end to end leave no neck, but
    each is thin at its ends), else at its necks."""
    mask = part[0]
    if not 0.0 < params.split_length_px < cv2.boundingRect(mask)[3]:
        return [part]
    contour = part[1] if part[1] is not None else _largest_contour(mask)
    return _split_by_height(mask, height, params, along=True) or _split_by_distance(mask, contour, params) or [part]


def _split_by_distance(component: np.ndarray, contour: np.ndarray,
                       params: SegmentationParams) -> list[tuple[np.ndarray, None]] | None:
    """A non-convex component split at its necks (distance-transform watershed), or None if it is one fillet."""
    distance = cv2.distanceTransform(component, cv2.DIST_L2, 5)
    cores = (distance > params.core_ratio * float(distance.max())).astype(np.uint8)
    n_cores, markers = cv2.connectedComponents(cores, connectivity=8, ltype=cv2.CV_32S)
    if n_cores <= 2:  # one core: one non-convex fillet, or two side by side along a long contact
        halves = _cut_between_notches(component, contour, params)
        if halves is None:
            return None
        n_cores, markers = 3, halves
    labels = _flood(distance, markers, component)
    return _region_masks(labels, range(1, n_cores))


def _split_by_height(component: np.ndarray, height: np.ndarray, params: SegmentationParams,
                     along: bool = False, floor: float | None = None) -> list[tuple[np.ndarray, None]] | None:
    """A wide component split into the fillets around its thick cores (height watershed), or None if it has one.

    Pixels higher than a fillet lying on the belt can be (past the roller edge the background is the floor) are
    left out of the relief: the cores are the middles of the fillets still on the belt. The cores are cut from
    the relief at ``height_core_ratio`` × its highest pixel first, then lower, down to ``height_core_floor``: a
    thin fillet beside a thick one rises above a lower cut only. ``along``: the cores lie one behind the other
    along the flow (a component too long for one fillet, so surely two), cut down to LONG_CORE_FLOOR. ``floor``:
    the lowest cut when it is not ``height_core_floor`` (fillets surely side by side).
    """
    relief = np.asarray(height, np.float32).copy()
    relief[(component == 0) | (relief > MAX_LYING_HEIGHT_M)] = 0.0
    top = float(relief.max())
    floor = LONG_CORE_FLOOR if along else floor or params.height_core_floor
    for ratio in np.arange(params.height_core_ratio, floor - 1e-9, -CORE_RATIO_STEP):
        markers, cores = _fillet_cores(cv2.compare(relief, float(ratio) * top, cv2.CMP_GT), params, along)
        if len(cores) >= 2:
            labels = _flood(relief, np.where(np.isin(markers, cores), markers, 0).astype(np.int32), component)
            return _region_masks(labels, cores)
    return None


def _fillet_cores(cores: np.ndarray, params: SegmentationParams, along: bool) -> tuple[np.ndarray, list[int]]:
    """The cores' labels and those large enough to be a fillet's middle that lie beside another such core (one
    behind another when ``along``)."""
    n_cores, markers, stats, _ = cv2.connectedComponentsWithStats(cores, connectivity=8, ltype=cv2.CV_32S)
    big = [c for c in range(1, n_cores) if stats[c, cv2.CC_STAT_AREA] * 8 >= params.min_area_px]
    return markers, [c for c in big if any(_side_by_side(stats[c], stats[d]) != along for d in big if d != c)]


def _split_by_priors(part: tuple[np.ndarray, np.ndarray | None], priors: Sequence[np.ndarray],
                     origin: tuple[int, int]) -> list[tuple[np.ndarray, np.ndarray | None]]:
    """The part, or the tracked fillets merged in it, each grown from where its prior outline lies.

    Two fillets that touch where neither a neck nor their heights part them (side by side as they tip over the
    roller, where the background falls to the floor) are one blob, and the tracker would follow one of them
    through it and lose the other. The tracker knows where each should lie: a blob that holds PRIOR_OVERLAP of
    two or more priors of a fillet's size and has grown past the largest (MERGE_AREA_RATIO) is split by a
    distance watershed from the priors' own pixels (less the pixels two of them claim). A sliver's prior (smaller
    than PRIOR_AREA_RATIO of the largest) never splits a fillet, nor do two priors of one fillet, which leave no
    growth. The fillets may lie side by side or one behind the other: a fillet whose front reaches the edge
    joins the remains of the lane-mate hanging ahead, whose prior, moved at the belt's speed as it falls, lies
    off it; what that prior claims of the follower's own prior is claimed twice and left to the watershed.
    """
    mask = part[0]
    held = [prior for prior in priors if _held(mask, prior, origin)]
    largest = max((cv2.contourArea(prior) for prior in held), default=0.0)
    held = [prior for prior in held if cv2.contourArea(prior) >= PRIOR_AREA_RATIO * largest]
    if len(held) < 2 or cv2.countNonZero(mask) < MERGE_AREA_RATIO * largest:
        return [part]
    markers = np.zeros(mask.shape, np.int32)
    claims = np.zeros(mask.shape, np.uint8)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (PRIOR_ERODE_PX, PRIOR_ERODE_PX))
    for label, prior in enumerate(held, start=1):
        core = cv2.erode(cv2.bitwise_and(_filled(prior, origin, mask.shape), mask), kernel)
        markers[core > 0] = label
        claims += core > 0
    markers[claims > 1] = 0
    labels = _flood(cv2.distanceTransform(mask, cv2.DIST_L2, 5), markers, mask)
    return _region_masks(labels, range(1, len(held) + 1))


def _split_by_tracks(parts: list[tuple[np.ndarray, np.ndarray | None]], priors: Sequence[np.ndarray],
                     origin: tuple[int, int], params: SegmentationParams) -> list[tuple[np.ndarray, np.ndarray | None]]:
    """A component's parts, each split into the tracked fillets merged in it (:func:`_split_by_priors`).

    A geometric split that cuts the prior of one tracked fillet into two parts is overruled: three fillets that
    enter the image side by side join into one blob whose notches part it through the middle one, which would
    then be tracked as two halves, each given a verdict. The parts that cut a prior are joined again and split
    from the priors instead (one fillet when that prior is the only one they hold); the other parts stand.
    Splitting the whole component from its priors would also cut a fillet the geometry parted cleanly, by the
    prior of a track that took a piece of its neighbour as they entered, and keep that piece with it frame after
    frame.
    """
    kept = []
    for group in _cut_groups(parts, priors, origin, params):
        if len(group) == 1:
            kept += _split_by_priors(parts[group[0]], priors, origin)
        else:
            kept += _split_by_priors((np.bitwise_or.reduce([parts[i][0] for i in group]), None), priors, origin)
    return kept


def _cut_groups(parts: Sequence[tuple[np.ndarray, np.ndarray | None]], priors: Sequence[np.ndarray],
                origin: tuple[int, int], params: SegmentationParams) -> list[list[int]]:
    """The parts' indices in groups joined by the priors they cut: two parts that each hold PRIOR_CUT_SHARE of a
    prior that can be one fillet (solid, no longer or larger than one lies; a track that followed two fillets
    joined end to end is rightly cut, and a turned fillet lies wider than a straight one) are in one group."""
    groups = [{i} for i in range(len(parts))]
    for prior in priors:
        area = cv2.contourArea(prior)
        if not 0.0 < area <= params.split_area_px or cv2.boundingRect(prior)[3] > params.split_length_px \
                or not _solid(prior, params):
            continue
        filled = _filled(prior, origin, parts[0][0].shape)  # every part is a mask of the component's ROI
        cut = {i for i, (mask, _) in enumerate(parts)
               if cv2.countNonZero(cv2.bitwise_and(filled, mask)) >= PRIOR_CUT_SHARE * area}
        if len(cut) >= 2:
            touched = [g for g in groups if g & cut]
            groups = [g for g in groups if not g & cut] + [set().union(*touched)]
    return [sorted(g) for g in groups]


def _solid(contour: np.ndarray, params: SegmentationParams) -> bool:
    """Whether an outline covers ``split_solidity`` of its convex hull (one fillet; less: maybe several)."""
    hull_area = cv2.contourArea(cv2.convexHull(contour))
    return hull_area <= 0.0 or cv2.contourArea(contour) / hull_area >= params.split_solidity


def _shared(start: int, length: int, other_start: int, other_length: int) -> int:
    """How much two spans of pixels overlap (negative: the gap between them)."""
    return min(start + length, other_start + other_length) - max(start, other_start)


def _rows_side_by_side(top: int, rows: int, other_top: int, other_rows: int) -> bool:
    """Whether two things spanning these rows share SIDE_BY_SIDE_OVERLAP of the shorter one's rows."""
    return _shared(top, rows, other_top, other_rows) >= SIDE_BY_SIDE_OVERLAP * min(rows, other_rows)


def _held(mask: np.ndarray, prior: np.ndarray, origin: tuple[int, int]) -> bool:
    """Whether ``mask`` (an ROI at ``origin``) covers PRIOR_OVERLAP of the prior outline's area."""
    area = cv2.contourArea(prior)
    u, v, width, height = cv2.boundingRect(prior)
    if area <= 0.0 or u + width <= origin[0] or v + height <= origin[1] or u >= origin[0] + mask.shape[1] \
            or v >= origin[1] + mask.shape[0]:
        return False
    inside = cv2.countNonZero(cv2.bitwise_and(_filled(prior, origin, mask.shape), mask))
    return inside >= PRIOR_OVERLAP * area


def _filled(outline: np.ndarray, origin: tuple[int, int], shape: tuple[int, ...]) -> np.ndarray:
    """The outline (image coordinates) filled into an ROI of ``shape`` at ``origin``."""
    filled = np.zeros(shape, np.uint8)
    cv2.fillPoly(filled, [np.asarray(outline, np.int32).reshape(-1, 2) - np.array(origin, np.int32)], 255)
    return filled


def _side_by_side(core: np.ndarray, other: np.ndarray) -> bool:
    """Whether two cores (connected-component stats rows) lie beside each other across the flow, sharing at least
    ``SIDE_BY_SIDE_OVERLAP`` of the shorter one's rows. A thick part ahead of or behind a core is the same fillet
    (a fillet reads thicker where it lies over the roller's crown, since the background falls away there) or a
    fillet one behind the other, which a neck separates (:func:`_split_by_distance`), never one beside it."""
    return _rows_side_by_side(core[cv2.CC_STAT_TOP], core[cv2.CC_STAT_HEIGHT], other[cv2.CC_STAT_TOP],
                              other[cv2.CC_STAT_HEIGHT])


def _region_masks(labels: np.ndarray, regions) -> list[tuple[np.ndarray, None]]:
    """One mask (255 inside) per watershed region, outlines still to be traced."""
    return [(np.where(labels == region, np.uint8(255), np.uint8(0)), None) for region in regions]


PRIOR_OVERLAP = 0.5
"""A blob holds a tracked fillet's prior outline when it covers this fraction of the prior's area."""
PRIOR_AREA_RATIO = 0.3
"""Priors smaller than this fraction of the largest one a blob holds are slivers and split nothing."""
PRIOR_CUT_SHARE = 0.25
"""A geometric split cuts a prior when two of its parts each cover this fraction of the prior's area."""
MERGE_AREA_RATIO = 1.25
"""A blob holding several priors is split only when it is this much larger than the largest of them."""
PRIOR_ERODE_PX = 5
"""The priors' pixels seed the split this far (kernel px) inside their outlines, off the contact."""
SIDE_BY_SIDE_OVERLAP = 0.25
"""Two thick cores split a wide component only when they share this fraction of the shorter core's rows."""
LONG_CORE_FLOOR = 0.35
"""The lowest cut of a too-long component's relief (× its highest pixel): two fillets touching end to end are thin
at their ends (a few mm where they meet, under a third of a thick fillet's middle), and the thinner one's middle
may stand at half the thicker one's."""
CORE_RATIO_STEP = 0.05
"""Step between the cuts of :func:`_split_by_height` (× the component's highest pixel)."""
MAX_LYING_HEIGHT_M = 0.1
"""No fillet lying on the belt is this thick; higher pixels are past the roller edge, over the floor."""
NOTCH_DEPTH_RATIO = 0.1
"""A concavity counts as the notch between two touching fillets when it is this deep × sqrt(component area)."""
FLOOD_LEVELS = 6
"""Immersion steps from the highest unlabelled pixel down to the border (~2 px apart on a fillet)."""


def _cut_between_notches(component: np.ndarray, contour: np.ndarray, params: SegmentationParams) -> np.ndarray | None:
    """Markers 1 and 2 on the two halves of a cut between the component's two deepest notches, or None.

    Fillets touching side by side along their length leave one distance core but
    a deep notch at each end of the contact; a single fillet has no second deep
    notch. None when there is no such pair of notches or a half is under ``min_area_px``.
    """
    hull = cv2.convexHull(contour, returnPoints=False)
    defects = cv2.convexityDefects(contour, hull) if len(hull) > 3 else None
    if defects is None or len(defects) < 2:
        return None
    defects = defects.reshape(-1, 4)
    deepest = defects[np.argsort(defects[:, 3])[-2:]]
    if deepest[:, 3].min() / 256.0 < NOTCH_DEPTH_RATIO * np.sqrt(cv2.countNonZero(component)):
        return None
    cut = component.copy()
    p1, p2 = (tuple(int(c) for c in contour[i].reshape(2)) for i in deepest[:, 2])
    cv2.line(cut, p1, p2, 0, 3)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(cut, connectivity=8, ltype=cv2.CV_32S)
    big = [i for i in range(1, count) if stats[i, cv2.CC_STAT_AREA] >= params.min_area_px]
    if len(big) != 2:
        return None
    markers = np.zeros(component.shape, np.int32)
    for new_label, old_label in enumerate(big, start=1):
        markers[labels == old_label] = new_label
    return markers


def _flood(distance: np.ndarray, markers: np.ndarray, component: np.ndarray, levels: int = FLOOD_LEVELS) -> np.ndarray:
    """Marker-controlled watershed of the inverted distance transform, by immersion in ``levels`` steps.

    Each step admits the unlabelled component pixels at least that far from the
    border and grows every labelled region into them by 3×3 geodesic dilation,
    so regions meet along the necks between fillets (:mod:`woody_vision.flood`).
    (cv2.watershed is not used: it floods by the difference between
    neighbouring pixels, not by elevation, so on a distance relief it runs along
    the flat rim and takes the other fillet's border.) Pixels reached by two
    regions at once go to the higher label.
    """
    unlabelled = cv2.bitwise_and(component, cv2.compare(markers, 0, cv2.CMP_EQ))
    if not cv2.countNonZero(unlabelled):
        return markers
    top = cv2.minMaxLoc(distance, unlabelled)[1]
    return flood(distance, markers, component, np.linspace(top, 0.0, levels + 1)[1:])


def _largest_contour(mask: np.ndarray) -> np.ndarray:
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    return max(contours, key=len)


def _make_blob(mask: np.ndarray, contour: np.ndarray | None, height_roi: np.ndarray, origin: tuple[int, int],
               min_area_px: int) -> Blob | None:
    area = cv2.countNonZero(mask)
    if area < min_area_px:
        return None
    moments = cv2.moments(mask, binaryImage=True)
    ox, oy = origin
    contour = (_largest_contour(mask) if contour is None else contour).reshape(-1, 2) + np.array([ox, oy], np.int32)
    bx, by, bw, bh = cv2.boundingRect(mask)
    return Blob(
        contour=contour.astype(np.int32),
        centroid=(moments["m10"] / moments["m00"] + ox, moments["m01"] / moments["m00"] + oy),
        area_px=int(area),
        bbox=(bx + ox, by + oy, bw, bh),
        mean_height_m=float(height_roi[mask > 0].mean()),
    )
