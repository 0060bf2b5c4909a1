"""Pinhole helpers for the nadir top camera: roller-edge row, belt-plane metres, lanes.

The top camera looks straight down at the belt from ``camera_height_m``. Image
rows (v) run downstream along the flow, image columns (u) run across the belt,
with world +y (towards lane 0) to the right of the image. Everything here is a
pure function of the CameraInfo ``K`` and a few line dimensions, so the ROS
nodes, the experiment runner and the tests agree on the same numbers.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

DEPTH_WINDOW_POINTS = 9
"""Contour points whose depth readings give one point's depth in :func:`belt_outline`."""
MAX_DROP_M = 0.12
"""Lowest a fillet's outline hangs below the belt while it is scored (its window closes when about half of a
0.17-0.22 m body is past the edge); a deeper reading at its border is the floor behind it, mixed in."""


@dataclass(frozen=True)
class Intrinsics:
    """Focal lengths and principal point in pixels (skew ignored: always 0 here)."""

    fx: float
    fy: float
    cx: float
    cy: float


def intrinsics_from_k(k: Sequence[float] | np.ndarray | Intrinsics) -> Intrinsics:
    """Read fx, fy, cx, cy from a row-major 9-float K (CameraInfo.k) or a 3x3 matrix."""
    if isinstance(k, Intrinsics):
        return k
    flat = np.asarray(k, dtype=float).reshape(-1)
    if flat.size != 9:
        raise ValueError(f"K must have 9 elements, got {flat.size}")
    if flat[0] <= 0.0 or flat[4] <= 0.0:
        raise ValueError(f"K has non-positive focal lengths fx={flat[0]}, fy={flat[4]}")
    return Intrinsics(fx=float(flat[0]), fy=float(flat[4]), cx=float(flat[2]), cy=float(flat[5]))


def edge_row(k: Sequence[float] | np.ndarray | Intrinsics, camera_height_m: float, edge_offset_m: float) -> float:
    """Image row of the roller edge, ``edge_offset_m`` downstream of the optical axis on the belt plane."""
    intr = intrinsics_from_k(k)
    return intr.cy + intr.fy * edge_offset_m / camera_height_m


def pixel_to_belt(
    u: float | np.ndarray,
    v: float | np.ndarray,
    k: Sequence[float] | np.ndarray | Intrinsics,
    camera_height_m: float,
) -> tuple[float | np.ndarray, float | np.ndarray]:
    """Back-project pixels onto the belt plane: (flow_m downstream of the optical axis, across_m = world y).

    Exact for points on the belt surface; points above it (fillet tops) come out
    slightly too far from the optical axis, by their height / camera height.
    """
    intr = intrinsics_from_k(k)
    flow_m = (np.asarray(v, dtype=float) - intr.cy) * camera_height_m / intr.fy
    across_m = (np.asarray(u, dtype=float) - intr.cx) * camera_height_m / intr.fx
    if np.ndim(flow_m) == 0:
        return float(flow_m), float(across_m)
    return flow_m, across_m


def belt_outline(contour: np.ndarray, depth: np.ndarray, k: Sequence[float] | np.ndarray | Intrinsics,
                 camera_height_m: float, window: int = DEPTH_WINDOW_POINTS) -> np.ndarray:
    """A contour with the perspective of the drop taken out: each point hanging below the belt where the camera
    would see its 3D point (at the z-depth under it) if that point lay on the belt plane, in pixels (int32, (N, 2)).

    A fillet bending down over the roller edge hangs below the belt; off the optical axis the camera sees the
    hanging part pulled towards the image centre by its drop / camera height times its distance from the axis,
    so one bend looks different in an outer lane than in the centre, and a turned fillet differently on either
    side of the axis. On this outline the shape change is the fillet's own. A point above the belt keeps its
    place: an outline point there is where the camera's ray grazes the fillet's side, a point that depends on
    which side the camera looks at, not the edge of the fillet's footprint, and moving it by its own height
    narrows the far side of a fillet in an outer lane by pixels (more as it tips); the fillet lies flat in its
    reference and on the belt, so its height changes nothing there that the score compares. Each point's depth
    is the median of the valid readings of the ``window`` contour points around it: a real camera's flying
    pixels and holes at an object's border are single points, the part hanging over the edge a stretch of
    them. A reading more than `MAX_DROP_M` below the belt is not valid (the floor behind the fillet), nor is
    NaN or 0; a point with no valid reading around it keeps its place.
    """
    intr = intrinsics_from_k(k)
    points = np.asarray(contour).reshape(-1, 2)
    rows = np.clip(points[:, 1], 0, depth.shape[0] - 1)
    cols = np.clip(points[:, 0], 0, depth.shape[1] - 1)
    z = depth[rows, cols].astype(np.float64)
    with np.errstate(invalid="ignore"):
        z[~((z > 0.0) & (z <= camera_height_m + MAX_DROP_M))] = np.nan
    z = _along_contour_median(z, window)
    scale = np.fmax(z, camera_height_m) / camera_height_m  # no reading (NaN) and above the belt: in place
    u = intr.cx + (points[:, 0] - intr.cx) * scale
    v = intr.cy + (points[:, 1] - intr.cy) * scale
    return np.round(np.stack([u, v], axis=1)).astype(np.int32)


def _along_contour_median(values: np.ndarray, window: int) -> np.ndarray:
    """The NaN-ignoring median of each value and its neighbours on a closed contour (``window`` points)."""
    if len(values) < window or window < 2:
        return values
    half = window // 2
    ring = np.concatenate([values[-half:], values, values[:half]])
    windows = np.lib.stride_tricks.sliding_window_view(ring, 2 * half + 1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a window of holes only stays NaN
        return np.nanmedian(windows, axis=1)


def lane_center_u(
    lane: int,
    k: Sequence[float] | np.ndarray | Intrinsics,
    camera_height_m: float,
    lanes: int,
    lane_pitch_m: float,
) -> float:
    """Image column of a lane centre on the belt plane (lane 0 is the rightmost)."""
    if not 0 <= lane < lanes:
        raise ValueError(f"lane must be in 0..{lanes - 1}, got {lane}")
    intr = intrinsics_from_k(k)
    y = ((lanes - 1) / 2.0 - lane) * lane_pitch_m
    return intr.cx + intr.fx * y / camera_height_m


def lane_of_u(
    u: float,
    k: Sequence[float] | np.ndarray | Intrinsics,
    camera_height_m: float,
    lanes: int,
    lane_pitch_m: float,
) -> int:
    """The lane whose centre is nearest to image column ``u`` (clamped to the outer lanes)."""
    _, across_m = pixel_to_belt(u, 0.0, k, camera_height_m)
    lane = round((lanes - 1) / 2.0 - float(across_m) / lane_pitch_m)
    return int(min(max(lane, 0), lanes - 1))


@dataclass(frozen=True)
class LaneLayout:
    """Everything needed to map an image column to a lane; handy to pass around as one value."""

    k: tuple[float, ...]
    camera_height_m: float
    lanes: int
    lane_pitch_m: float

    def __post_init__(self) -> None:
        intrinsics_from_k(self.k)
        object.__setattr__(self, "k", tuple(float(x) for x in np.asarray(self.k, dtype=float).reshape(-1)))
        if self.camera_height_m <= 0.0:
            raise ValueError(f"camera_height_m must be > 0, got {self.camera_height_m}")
        if self.lanes < 1:
            raise ValueError(f"lanes must be >= 1, got {self.lanes}")
        if self.lane_pitch_m <= 0.0:
            raise ValueError(f"lane_pitch_m must be > 0, got {self.lane_pitch_m}")

    def lane_of_u(self, u: float) -> int:
        """Lane of an image column."""
        return lane_of_u(u, self.k, self.camera_height_m, self.lanes, self.lane_pitch_m)

    def lane_center_u(self, lane: int) -> float:
        """Image column of a lane centre."""
        return lane_center_u(lane, self.k, self.camera_height_m, self.lanes, self.lane_pitch_m)
