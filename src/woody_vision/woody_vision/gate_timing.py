"""When a lane's diverter must open for a fillet: plain arithmetic the reject gate and tests share."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

GATE_DISTANCE_M = 0.6
"""Distance from the roller edge to a lane's diverter (m), the reject gate's default."""
GATE_DISTANCE_RANGE_M = (0.05, 20.0)
"""Diverter distances a gate accepts (m): from just past the roller to the far end of a long take-away belt."""


@dataclass(frozen=True)
class GateTiming:
    """Line speed and diverter positions; times are sim seconds."""

    line_speed_mps: float
    gate_distances_m: Sequence[float]
    open_duration_s: float = 0.3

    def __post_init__(self) -> None:
        if self.line_speed_mps <= 0:
            raise ValueError(f"line speed must be > 0 m/s, got {self.line_speed_mps}")
        low, high = GATE_DISTANCE_RANGE_M
        if not self.gate_distances_m or not all(low <= d <= high for d in self.gate_distances_m):
            raise ValueError(f"gate distances must be in [{low:g}, {high:g}] m, got {list(self.gate_distances_m)}")
        if self.open_duration_s <= 0:
            raise ValueError(f"open duration must be > 0 s, got {self.open_duration_s}")

    def actuation_time(self, lane: int, edge_crossing_time: float, speed_mps: float = math.nan) -> float:
        """Sim time to open the gate so it is open while the fillet's centre passes.

        ``speed_mps`` is the fillet's measured speed; without a plausible one
        (finite, within a factor 2 of the line speed) the line speed is used.
        """
        if not 0 <= lane < len(self.gate_distances_m):
            raise ValueError(f"lane {lane} has no diverter (lanes 0..{len(self.gate_distances_m) - 1})")
        plausible = math.isfinite(speed_mps) and 0.5 <= speed_mps / self.line_speed_mps <= 2.0
        travel = self.gate_distances_m[lane] / (speed_mps if plausible else self.line_speed_mps)
        return edge_crossing_time + travel - self.open_duration_s / 2.0
