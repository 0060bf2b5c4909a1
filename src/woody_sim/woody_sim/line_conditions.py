"""How untidy the line is: each fillet's turn, leading end, place in its lane and size, seeded and reproducible.

A plain module (no rclpy) so that ``line_sim`` and the headless sweep lay the same fillet the same way.
:func:`placement_for` draws a fillet's placement from the run's seed and the fillet's spawn index alone, so
a fillet lies the same way whatever was drawn before it; :func:`place_mesh` turns and sizes its mesh.
Lengths in metres, angles in degrees (the user-facing unit of a turn, as ``--yaw-sd``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr, ndtri

from woody_sim.meshes import MAX_YAW_SD_DEG, FilletMesh, scaled, yawed

MAX_YAW_DEG = 45.0
"""Widest turn: beyond it a fillet lies across the belt rather than turned on it (end-swaps are blunt_fraction)."""
MAX_LATERAL_M = 0.05
"""Largest offset of a fillet's centre from its lane centre (line_sim also keeps it within half the lane pitch)."""
SCALE_RANGE = (0.5, 1.5)
"""Size factors accepted: within it a fillet stays a chicken breast (0.09-0.31 m long from the 0.17-0.21 m meshes)."""
PLACEMENT_STREAM = 23
"""Second seed word of the placement draws (the first is the run's seed, the third the spawn index)."""


@dataclass(frozen=True)
class LineConditions:
    """The spread of placements on a line; the defaults are the tidy line (straight, narrow end first, centred).

    A fillet's yaw is normal with sd ``yaw_sd_deg`` truncated to +-``yaw_max_deg`` (None: 2 sd, at most
    MAX_YAW_DEG); its lateral offset likewise with ``lateral_sd_m`` and ``lateral_max_m`` (None: 2 sd). A
    ``blunt_fraction`` of fillets arrive blunt end first (turned 180 deg about the vertical). The size factor s
    is uniform in ``scale_min..scale_max``; the chain's mass is M * s**3, as mass follows volume.
    """

    yaw_sd_deg: float = 0.0
    yaw_max_deg: float | None = None
    blunt_fraction: float = 0.0
    lateral_sd_m: float = 0.0
    lateral_max_m: float | None = None
    scale_min: float = 1.0
    scale_max: float = 1.0

    def __post_init__(self) -> None:
        _check(0.0 <= self.yaw_sd_deg <= MAX_YAW_SD_DEG, f"yaw_sd_deg must be within 0..{MAX_YAW_SD_DEG:g} deg",
               self.yaw_sd_deg)
        if self.yaw_max_deg is None:
            object.__setattr__(self, "yaw_max_deg", min(2.0 * self.yaw_sd_deg, MAX_YAW_DEG))
        _check(0.0 <= self.yaw_max_deg <= MAX_YAW_DEG, f"yaw_max_deg must be within 0..{MAX_YAW_DEG:g} deg",
               self.yaw_max_deg)
        _check(0.0 <= self.blunt_fraction <= 1.0, "blunt_fraction must be within 0..1", self.blunt_fraction)
        _check(0.0 <= self.lateral_sd_m <= MAX_LATERAL_M, f"lateral_sd_m must be within 0..{MAX_LATERAL_M:g} m",
               self.lateral_sd_m)
        if self.lateral_max_m is None:
            object.__setattr__(self, "lateral_max_m", min(2.0 * self.lateral_sd_m, MAX_LATERAL_M))
        _check(0.0 <= self.lateral_max_m <= MAX_LATERAL_M, f"lateral_max_m must be within 0..{MAX_LATERAL_M:g} m",
               self.lateral_max_m)
        low, high = SCALE_RANGE
        _check(low <= self.scale_min <= high, f"scale_min must be within {low:g}..{high:g}", self.scale_min)
        _check(low <= self.scale_max <= high, f"scale_max must be within {low:g}..{high:g}", self.scale_max)
        _check(self.scale_min <= self.scale_max, f"scale_max must be >= scale_min {self.scale_min:g}",
               self.scale_max)


def _check(ok: bool, message: str, value: float) -> None:
    """One ValueError line naming the rule and the value (a NaN fails every rule)."""
    if not ok:
        raise ValueError(f"{message}, got {value!r}")


@dataclass(frozen=True)
class FilletPlacement:
    """How one fillet lies: turned ``yaw_deg`` (towards +y), maybe blunt end first, ``lateral_offset_m`` along +y
    from its lane centre, its mesh scaled by ``scale``."""

    yaw_deg: float = 0.0
    blunt_first: bool = False
    lateral_offset_m: float = 0.0
    scale: float = 1.0

    @property
    def keeps_mesh(self) -> bool:
        """The mesh lies as loaded (straight, narrow end first, full size): no new mesh to build."""
        return (self.yaw_deg, self.blunt_first, self.scale) == (0.0, False, 1.0)


LINE_PRESETS: dict[str, LineConditions] = {
    "tidy": LineConditions(),
    # The mixed line: yaw sd 15 deg (bound 35: never across the belt), half blunt end first, the centre
    # within 2.5 cm of the lane centre (sd 1 cm), and sizes x0.85-1.15 (mass x0.61-1.52).
    "messy": LineConditions(yaw_sd_deg=15.0, yaw_max_deg=35.0, blunt_fraction=0.5, lateral_sd_m=0.01,
                            lateral_max_m=0.025, scale_min=0.85, scale_max=1.15),
}
"""Named lines (line_sim's ``line`` parameter)."""


def line_preset(name: str) -> LineConditions:
    """The named line's conditions; a ValueError names the known presets."""
    if name not in LINE_PRESETS:
        raise ValueError(f"unknown line preset {name!r}; known: {', '.join(LINE_PRESETS)}")
    return LINE_PRESETS[name]


def _truncated_normal(u: float, sd: float, bound: float) -> float:
    """The normal(0, sd) value truncated to +-bound at quantile ``u`` (inverse CDF: one draw, never a redraw)."""
    if sd <= 0.0 or bound <= 0.0:
        return 0.0
    edge = float(ndtr(bound / sd))
    return float(sd * ndtri((1.0 - edge) + u * (2.0 * edge - 1.0)))


def draw_placement(conditions: LineConditions, rng: np.random.Generator) -> FilletPlacement:
    """One fillet's placement; always four uniform draws, so one knob never shifts another's."""
    u_yaw, u_blunt, u_lateral, u_scale = rng.random(4)
    c = conditions
    return FilletPlacement(
        yaw_deg=_truncated_normal(u_yaw, c.yaw_sd_deg, c.yaw_max_deg),
        blunt_first=bool(u_blunt < c.blunt_fraction),
        lateral_offset_m=_truncated_normal(u_lateral, c.lateral_sd_m, c.lateral_max_m),
        scale=float(c.scale_min + u_scale * (c.scale_max - c.scale_min)),
    )


def placement_for(conditions: LineConditions, seed: int, index: int) -> FilletPlacement:
    """The placement of the ``index``-th spawned fillet of a run seeded ``seed``, whatever was drawn before."""
    return draw_placement(conditions, np.random.default_rng([int(seed), PLACEMENT_STREAM, int(index)]))


def place_mesh(mesh: FilletMesh, placement: FilletPlacement) -> FilletMesh:
    """The mesh as the fillet lies: scaled, turned 180 deg if blunt end first, then yawed, re-centred.

    The mesh itself when the placement keeps it (so a tidy line reuses every chain model it built at start).
    """
    if placement.keeps_mesh:
        return mesh
    sized = scaled(mesh, placement.scale) if placement.scale != 1.0 else mesh
    turn = placement.yaw_deg + (180.0 if placement.blunt_first else 0.0)
    return yawed(sized, turn) if turn else sized


def placed_extent(mesh: FilletMesh, yaw_deg: float, scale: float = 1.0) -> float:
    """Extent (m) along the flow of the mesh's footprint box turned by ``yaw_deg`` and sized by ``scale``: an upper
    bound of the placed fillet's (a blunt-first end swap leaves it unchanged)."""
    turn = math.radians(abs(yaw_deg))
    return scale * (mesh.length * math.cos(turn) + mesh.width * math.sin(turn))


def longest_placed_length(meshes: list[FilletMesh], conditions: LineConditions) -> float:
    """Upper bound (m) of a placed fillet's extent along the flow: its footprint box at the largest size, turned
    by the yaw within the bound that lengthens it most (what in-lane spacing must exceed for fillets not to
    overlap)."""
    def extent(mesh: FilletMesh) -> float:
        return placed_extent(mesh, min(conditions.yaw_max_deg, math.degrees(math.atan2(mesh.width, mesh.length))))

    return conditions.scale_max * max((extent(m) for m in meshes), default=0.0)


def crowding_note(spacing_m: float, longest_m: float) -> str:
    """What line_sim logs (and `woody run` says before it starts) when in-lane spacing is below the longest placed
    fillet ('' when it is not)."""
    if spacing_m >= longest_m:
        return ""
    return (f"in-lane spacing {spacing_m:.3f} m is below the longest placed fillet ({longest_m:.3f} m): a fillet "
            "waits at the spawn point until it has room, so a lane may carry fewer fillets than its spacing says")


MEAN_PLACEMENT_DRAWS = 1000
"""Placements (seed 0, the first spawn indices) that :func:`mean_placed_length` averages over."""


def mean_placed_length(meshes: list[FilletMesh], conditions: LineConditions) -> float:
    """Mean extent (m) along the flow of a placed fillet: every mesh's footprint box under each of
    MEAN_PLACEMENT_DRAWS placements line_sim would draw (what in-lane spacing exceeds by the mean gap)."""
    placements = [placement_for(conditions, 0, index) for index in range(MEAN_PLACEMENT_DRAWS)]
    return float(np.mean([placed_extent(m, p.yaw_deg, p.scale) for m in meshes for p in placements]))
