"""The line conditions a sweep grades under: the tidy line, each disturbance of the messy line alone, and all.

Each is a :class:`woody_sim.line_conditions.LineConditions`; the messy
preset's numbers are defined once (``woody_sim.line_conditions.LINE_PRESETS``)
and each single disturbance takes its own from there. A run's placement is
drawn from its mesh, condition and speed (:func:`run_placement`), so the
normal and woody versions of a mesh lie the same way (paired runs), and a
rerun lies the same way. A sweep's lanes are copies of one chain, so a lateral
offset moves every lane's copy alike.
"""

from __future__ import annotations

import zlib

from woody_sim.line_conditions import MAX_YAW_DEG, FilletPlacement, LineConditions, line_preset, placement_for

_MESSY = line_preset("messy")
TIDY = "tidy"
SWEEP_CONDITIONS: dict[str, LineConditions] = {
    TIDY: line_preset(TIDY),
    "turned": LineConditions(yaw_sd_deg=_MESSY.yaw_sd_deg, yaw_max_deg=_MESSY.yaw_max_deg),
    "blunt": LineConditions(blunt_fraction=1.0),
    "size": LineConditions(scale_min=_MESSY.scale_min, scale_max=_MESSY.scale_max),
    "messy": _MESSY,
    "wide": LineConditions(yaw_sd_deg=MAX_YAW_DEG, yaw_max_deg=MAX_YAW_DEG, blunt_fraction=0.5,
                           scale_min=_MESSY.scale_min, scale_max=_MESSY.scale_max),
}
"""Condition name -> how fillets lie: tidy; turned (the messy yaw alone); blunt (every fillet blunt end first);
size (the messy size spread alone); messy (all of it, half blunt end first); wide (turns spread over every turn
the line allows, up to MAX_YAW_DEG, half blunt end first: the turned fillets, stiff and blunt first among them,
that the messy line draws rarely)."""


def sweep_condition(name: str) -> LineConditions:
    """The named condition; a ValueError lists the known ones."""
    if name not in SWEEP_CONDITIONS:
        raise ValueError(f"unknown condition {name!r}; known: {', '.join(SWEEP_CONDITIONS)}")
    return SWEEP_CONDITIONS[name]


def run_placement(mesh: str, condition: str, speed_fpm: float) -> FilletPlacement:
    """How a run's fillet lies: drawn from the mesh, the condition and the speed (the same at every k)."""
    return placement_for(sweep_condition(condition), zlib.crc32(f"{mesh}|{condition}".encode()),
                         round(speed_fpm * 10))
