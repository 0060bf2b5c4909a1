"""Room at the spawn point: a fillet is laid on the belt only where no other fillet lies (no rclpy).

Chains do not collide with each other (woody_sim.line_world), so the line itself must not lay a fillet into
another: on a crowded line (lanes closer than a turned fillet is wide, fillets of a lane as close as they are
long) two fillets side by side would otherwise overlap on the belt, a blob no real line shows. Each fillet's
footprint is the convex hull of its placed mesh seen from above, carried along the flow by the belt; a
scheduled fillet waits at the spawn point until its footprint is clear of every other, as a fillet waits in
the hand of whoever lays it on a full belt. Hulls may touch: touching fillets are a real line's.
"""

from __future__ import annotations

import cv2
import numpy as np

OVERLAP_AREA_M2 = 1e-6
"""Footprints sharing more than this area (1 mm²) overlap; less is touching, within the hulls' round-off."""


def footprint(vertices: np.ndarray, x: float, y: float) -> np.ndarray:
    """(K, 2) float32 convex hull of a placed mesh's vertices seen from above, its frame at (x, y) on the belt."""
    hull = cv2.convexHull(np.asarray(vertices, dtype=np.float32)[:, :2].copy())
    return hull.reshape(-1, 2) + np.array([x, y], dtype=np.float32)


def overlap_area(a: np.ndarray, b: np.ndarray) -> float:
    """Area (m²) two convex footprints share."""
    if a[:, 0].max() <= b[:, 0].min() or b[:, 0].max() <= a[:, 0].min():
        return 0.0
    if a[:, 1].max() <= b[:, 1].min() or b[:, 1].max() <= a[:, 1].min():
        return 0.0
    area, _ = cv2.intersectConvexConvex(a.reshape(-1, 1, 2), b.reshape(-1, 1, 2))
    return max(0.0, float(area))


class SpawnClearance:
    """The footprints laid near the spawn point and how far the belt has carried them since."""

    def __init__(self, reach_m: float) -> None:
        if not reach_m > 0.0:
            raise ValueError(f"reach must be > 0 m, got {reach_m}")
        self.reach_m = float(reach_m)
        """A footprint carried this far past the spawn point can no longer meet a new one (the longest fillet)."""
        self._travel = 0.0
        self._laid: list[tuple[np.ndarray, float]] = []
        """(footprint as laid, belt travel then)."""

    def advance(self, distance_m: float) -> None:
        """The belt moved ``distance_m`` (m) along the flow."""
        self._travel += float(distance_m)
        self._laid = [(shape, at) for shape, at in self._laid if self._travel - at <= self.reach_m]

    def clear(self, shape: np.ndarray) -> bool:
        """Whether a footprint laid at the spawn point now overlaps none laid before."""
        return all(overlap_area(shape, self._carried(laid, at)) <= OVERLAP_AREA_M2 for laid, at in self._laid)

    def lay(self, shape: np.ndarray) -> None:
        """A fillet was laid at the spawn point with this footprint (a longer one than any before widens the
        reach)."""
        self.reach_m = max(self.reach_m, float(np.ptp(shape[:, 0])))
        self._laid.append((shape, self._travel))

    def _carried(self, shape: np.ndarray, at: float) -> np.ndarray:
        return shape + np.array([self._travel - at, 0.0], dtype=np.float32)
