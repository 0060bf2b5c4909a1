"""Shape descriptors of fillet meshes, so a generated set can be compared with reference meshes.

Every descriptor is measured on the *footprint outline*: the mesh's top surface
is rasterised at :data:`FOOTPRINT_PIXEL` (a height map, as a nadir depth camera
sees it), thresholded at :data:`FOOTPRINT_HEIGHT_M`, and the outer contour of
that mask is resampled every pixel and smoothed with a Gaussian of
:data:`CONTOUR_SIGMA_M` along its length. The smoothing removes the contour's own
pixel staircase (so a disc or a rectangle scores a rim roughness of 1.00) but
keeps every step or wiggle of a millimetre or more, which a camera contour keeps
too. Definitions (canonical frame: x = length, tip at +x):

* aspect ratio: outline length along x / max width;
* width at p: the outline's extent across y at x = x_min + p·length, as a
  fraction of the max width (the same measure over all x);
* solidity: outline area / convex-hull area;
* rim roughness: outline perimeter / convex-hull perimeter;
* thickness: highest point of the mesh above its bottom (m);
* fullness: mean height over the footprint / thickness (a flat slab 1, a
  dome lower: how the thickness is spread, which sets the segment masses);
* area: area inside the outline (m²).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

import cv2
import numpy as np
from scipy import ndimage

from woody_sim.meshes import FilletMesh, HeightMap, rasterize_top

FOOTPRINT_PIXEL = 0.00025
"""Rasterisation pitch (m): eight times finer than the top camera's ~2 mm at the belt."""
FOOTPRINT_HEIGHT_M = 1e-4
"""Heights above this (m) belong to the footprint: the plan-view silhouette of the fillet."""
CONTOUR_SIGMA_M = 0.0005
"""Gaussian smoothing of the outline along its length (m): two raster pixels, a quarter of a camera pixel."""
WIDTH_STATIONS = (0.10, 0.25, 0.50, 0.75, 0.90)
"""Fractions of the length (from the trailing end at -x to the tip at +x) where widths are reported."""
_WIDTH_SCAN = 400
"""Number of cross-sections scanned for the max width."""


@dataclass(frozen=True)
class Descriptors:
    """One mesh's descriptors (see the module docstring for the definitions)."""

    name: str
    aspect_ratio: float
    solidity: float
    rim_roughness: float
    width_10: float
    width_25: float
    width_50: float
    width_75: float
    width_90: float
    thickness_m: float
    fullness: float
    area_m2: float

    def values(self) -> dict[str, float]:
        """The numeric descriptors by name (everything but the name)."""
        return {k: v for k, v in asdict(self).items() if k != "name"}


DESCRIPTOR_NAMES = tuple(f.name for f in fields(Descriptors) if f.name != "name")


def footprint_outline(height_map: HeightMap, threshold: float = FOOTPRINT_HEIGHT_M,
                      sigma: float = CONTOUR_SIGMA_M) -> np.ndarray:
    """Closed outline (N, 2) in metres of the largest region of the height map above ``threshold``."""
    mask = np.ascontiguousarray(height_map.heights > threshold, dtype=np.uint8)
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        raise ValueError("the height map has no footprint above the threshold")
    pixels = max(contours, key=cv2.contourArea).reshape(-1, 2).astype(float)
    if len(pixels) < 8:
        raise ValueError("the footprint is too small to have an outline")
    points = np.column_stack([height_map.x0 + pixels[:, 0] * height_map.pixel,
                              height_map.y0 + pixels[:, 1] * height_map.pixel])
    return smooth_outline(points, height_map.pixel, sigma)


def smooth_outline(points: np.ndarray, step: float, sigma: float) -> np.ndarray:
    """The closed polyline resampled every ``step`` (m) of length and Gaussian-smoothed by ``sigma`` (m)."""
    closed = np.vstack([points, points[:1]])
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
    count = max(8, int(round(arc[-1] / step)))
    at = np.arange(count) * arc[-1] / count
    resampled = np.column_stack([np.interp(at, arc, closed[:, 0]), np.interp(at, arc, closed[:, 1])])
    if sigma <= 0.0:
        return resampled
    return ndimage.gaussian_filter1d(resampled, sigma * count / arc[-1], axis=0, mode="wrap")


def perimeter(outline: np.ndarray) -> float:
    """Length of a closed polyline."""
    return float(np.linalg.norm(np.diff(np.vstack([outline, outline[:1]]), axis=0), axis=1).sum())


def area(outline: np.ndarray) -> float:
    """Area enclosed by a simple closed polyline (shoelace)."""
    x, y = outline[:, 0], outline[:, 1]
    return float(0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def convex_hull(outline: np.ndarray) -> np.ndarray:
    """Convex hull of the outline's points, as a closed polyline."""
    return cv2.convexHull(outline.astype(np.float32)).reshape(-1, 2).astype(float)


def widths_across(outline: np.ndarray, xs: np.ndarray) -> np.ndarray:
    """Extent across y of the outline at each x (0 where the line misses it)."""
    a, b = outline, np.roll(outline, -1, axis=0)
    lo, hi = np.minimum(a[:, 0], b[:, 0]), np.maximum(a[:, 0], b[:, 0])
    widths = np.zeros(len(xs))
    for i, x in enumerate(xs):
        hit = (lo <= x) & (x < hi)
        if hit.sum() < 2:
            continue
        t = (x - a[hit, 0]) / (b[hit, 0] - a[hit, 0])
        y = a[hit, 1] + t * (b[hit, 1] - a[hit, 1])
        widths[i] = y.max() - y.min()
    return widths


def describe_outline(outline: np.ndarray, thickness: float, fullness: float, name: str = "") -> Descriptors:
    """Descriptors of one footprint outline (metres, canonical frame), the mesh thickness and fullness."""
    x_min, x_max = float(outline[:, 0].min()), float(outline[:, 0].max())
    length = x_max - x_min
    scan = widths_across(outline, np.linspace(x_min, x_max, _WIDTH_SCAN + 2)[1:-1])
    max_width = float(scan.max())
    if length <= 0.0 or max_width <= 0.0:
        raise ValueError(f"{name or 'outline'}: degenerate footprint")
    stations = widths_across(outline, x_min + np.asarray(WIDTH_STATIONS) * length) / max_width
    hull = convex_hull(outline)
    return Descriptors(
        name=name,
        aspect_ratio=length / max_width,
        solidity=area(outline) / area(hull),
        rim_roughness=perimeter(outline) / perimeter(hull),
        **{f"width_{round(p * 100)}": float(w) for p, w in zip(WIDTH_STATIONS, stations)},
        thickness_m=float(thickness),
        fullness=float(fullness),
        area_m2=area(outline),
    )


def describe(fillet: FilletMesh, threshold: float = FOOTPRINT_HEIGHT_M) -> Descriptors:
    """Descriptors of one fillet, its footprint rasterised at :data:`FOOTPRINT_PIXEL`.

    ``threshold`` is the height (m) the footprint starts at: the default gives
    the plan-view silhouette, the segmenter's 5 mm the contour Φ is taken on.
    """
    height_map = rasterize_top(fillet.mesh.vertices, fillet.mesh.faces, FOOTPRINT_PIXEL)
    fullness = height_map.heights[height_map.heights > threshold].mean() / fillet.thickness
    return describe_outline(footprint_outline(height_map, threshold), fillet.thickness, fullness, fillet.name)


def summarize(descriptors: list[Descriptors]) -> dict[str, dict[str, float]]:
    """Per descriptor over a set: mean, sd (sample, 0 for one mesh), min and max."""
    if not descriptors:
        raise ValueError("no meshes to summarise")
    summary = {}
    for key in DESCRIPTOR_NAMES:
        values = np.array([d.values()[key] for d in descriptors])
        sd = float(values.std(ddof=1)) if len(values) > 1 else 0.0
        summary[key] = {"mean": float(values.mean()), "sd": sd, "min": float(values.min()), "max": float(values.max())}
    return summary


def outside_range(summary: dict[str, dict[str, float]], reference: dict[str, dict[str, float]]) -> list[str]:
    """Descriptors whose set mean lies outside the reference set's min..max (empty when all are inside)."""
    return [key for key in DESCRIPTOR_NAMES
            if not reference[key]["min"] <= summary[key]["mean"] <= reference[key]["max"]]

