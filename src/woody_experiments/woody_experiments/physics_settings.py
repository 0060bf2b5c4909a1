"""What each physics setting costs and what it changes in the scores: the settings table of docs/physics.md.

A cheaper physics that leaves every score where the paper's chain puts it is the same science, faster; one that
moves the scores is a trade-off. For each setting (:data:`SETTINGS`, PhysicsConfig overrides) this measures

* its cost: wall seconds per simulated second of a line of fillets (woody_tools' physics benchmark, the same
  LineWorld line_sim steps; per second, not per step, so that steps of another length compare), beside the
  paper chain's, timed in the same run;
* what it changes: the same runs as `woody sweep` evaluates (:func:`~woody_experiments.experiment.evaluate_run`,
  tidy line, every lane), each fillet's Φ, ``line_phi``, NMDM and BE against the paper chain's, as
  |ln(setting / paper)|, and how many runs the calibrated cut still grades right;
* the yardstick: the paper's chain against itself with the fillet spawned a third of a camera frame later
  (``spawn_offset_m``; not a whole number of physics steps either), how much a score moves from one fillet of
  a line to the next without any change to the physics. A setting whose changes stay inside that spread
  changes nothing the project measures.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from woody_common.calibration import resolved_calibration
from woody_common.line import fpm_to_mps
from woody_experiments.experiment import TOP_RATE_HZ, RunSpec, evaluate_run
from woody_experiments.line_grade import conditions_of
from woody_sim.line_world import PAPER_PHYSICS, PhysicsConfig, calibrated_config
from woody_sim.meshes import FilletMesh
from woody_vision.grader_core import calibrated_rules
from woody_vision.grading import GradingRules

SETTINGS: dict[str, dict] = {
    "40 slices, 480 Hz, 20 iterations": PAPER_PHYSICS,
    "10 solver iterations": {**PAPER_PHYSICS, "solver_iterations": 10},
    "5 solver iterations": {**PAPER_PHYSICS, "solver_iterations": 5},
    "360 Hz": {**PAPER_PHYSICS, "dt": 1.0 / 360.0},
    "240 Hz": {**PAPER_PHYSICS, "dt": 1.0 / 240.0},
    "360 Hz, 10 iterations": {**PAPER_PHYSICS, "dt": 1.0 / 360.0, "solver_iterations": 10},
    "240 Hz, 10 iterations": {**PAPER_PHYSICS, "dt": 1.0 / 240.0, "solver_iterations": 10},
    "30 slices": {**PAPER_PHYSICS, "n_segments": 30},
    "20 slices": {**PAPER_PHYSICS, "n_segments": 20},
    "30 slices, 360 Hz": {"n_segments": 30, "dt": 1.0 / 360.0},
    "24 slices, 360 Hz (the default)": {"n_segments": 24, "dt": 1.0 / 360.0},
    "20 slices, 360 Hz": {"n_segments": 20, "dt": 1.0 / 360.0},
    "24 slices, 360 Hz, capsule slices": {"n_segments": 24, "dt": 1.0 / 360.0, "slice_shape": "capsule"},
    "24 slices, 360 Hz, island sleeping": {"n_segments": 24, "dt": 1.0 / 360.0, "island_sleeping": True},
}
"""Name -> PhysicsConfig overrides; the first is the paper's chain (20 solver iterations), which every other is
compared with."""
REFERENCE = next(iter(SETTINGS))
SPREAD = "the paper's chain, a third of a frame later"
"""The yardstick row: the paper chain's own run-to-run spread."""
SPREAD_FRAMES = 1.0 / 3.0
"""How much later (camera frames) the yardstick row spawns each fillet."""
SCORES = ("phi", "line_phi", "nmdm", "be")


@dataclass(frozen=True)
class SettingFigures:
    """One row of the table."""

    name: str
    wall_per_sim_s: float
    """Wall seconds per simulated second of the timed line (NaN for the yardstick row)."""
    speedup: float
    """The paper chain's wall seconds per simulated second over this setting's."""
    changes: dict[str, tuple[float, float]]
    """Score -> (median, max) |ln(setting / paper)| over the fillets."""
    right: int
    """Runs (median over their lanes) the calibrated reject cut grades right, normal k = 0 vs severe k > 0."""
    runs: int


def evaluate_settings(meshes: list[FilletMesh], ks: list[float], speeds: list[float],
                      cost: Callable[[PhysicsConfig], float],
                      progress: Callable[[str], None] | None = None) -> list[SettingFigures]:
    """Every setting of :data:`SETTINGS` and the yardstick row, measured over meshes × ks × speeds; ``cost`` times
    a config (wall seconds per simulated second of a line, woody_tools.benchmarks.physics)."""
    calibration = resolved_calibration()
    specs = [RunSpec(mesh=m.name, k=k, speed_fpm=s) for m in meshes for k in ks for s in speeds]
    by_name = {m.name: m for m in meshes}

    def rows_of(overrides: dict, offset_frames: float = 0.0) -> dict:
        config = calibrated_config(calibration, **overrides)
        out = {}
        for spec in specs:
            shift = offset_frames * fpm_to_mps(spec.speed_fpm) / TOP_RATE_HZ
            out[spec] = evaluate_run(replace(spec, spawn_offset_m=shift), by_name[spec.mesh], config)
        return out

    reference = SETTINGS[REFERENCE]
    baseline = rows_of(reference)
    rules = calibrated_rules(calibration)
    paper_cost = cost(calibrated_config(calibration, **reference))
    figures = [_figures(REFERENCE, paper_cost, paper_cost, baseline, baseline, rules),
               _figures(SPREAD, math.nan, paper_cost, rows_of(reference, SPREAD_FRAMES), baseline, rules)]
    for name, overrides in list(SETTINGS.items())[1:]:
        if progress is not None:
            progress(name)
        spent = cost(calibrated_config(calibration, **overrides))
        figures.append(_figures(name, spent, paper_cost, rows_of(overrides), baseline, rules))
    return figures


def _figures(name: str, spent: float, paper_cost: float, rows: dict, baseline: dict,
             rules: GradingRules) -> SettingFigures:
    changes = {score: _changes(rows, baseline, score) for score in SCORES}
    right = sum(_graded_right(lanes, rules) for lanes in rows.values())
    speedup = paper_cost / spent if math.isfinite(spent) else math.nan
    return SettingFigures(name, spent, speedup, changes, right, len(rows))


def _changes(rows: dict, baseline: dict, score: str) -> tuple[float, float]:
    """(median, max) |ln(new / paper)| of one score over every lane row both runs measured."""
    moved = [abs(math.log(new[score] / old[score])) for spec in rows for new, old in zip(rows[spec], baseline[spec])
             if new[score] > 0 and old[score] > 0]
    return (float(np.median(moved)), float(np.max(moved))) if moved else (math.nan, math.nan)


def _graded_right(lanes: list[dict], rules: GradingRules) -> bool:
    """Whether the run's vote (the median of its lanes' verdicts, each lane's line score against its own cut) is
    right."""
    votes = [rules.is_woody(row["line_phi"], conditions_of(row)) for row in lanes if math.isfinite(row["line_phi"])]
    return bool(votes) and (sorted(votes)[len(votes) // 2] == (lanes[0]["k"] > 0))


def markdown_table(figures: list[SettingFigures]) -> str:
    """The table of docs/physics.md."""
    head = ("| setting | wall s per sim-s | speed-up | " + " | ".join(f"{s} moved (median / max)" for s in SCORES)
            + " | runs graded right |")
    lines = [head, "|" + "---|" * (5 + len(SCORES) - 1)]
    for f in figures:
        cost = "—" if not math.isfinite(f.wall_per_sim_s) else f"{f.wall_per_sim_s:.3f}"
        speed = "—" if not math.isfinite(f.speedup) else f"{f.speedup:.2f}×"
        moved = " | ".join(f"{100 * a:.1f} % / {100 * b:.1f} %" for a, b in (f.changes[s] for s in SCORES))
        lines.append(f"| {f.name} | {cost} | {speed} | {moved} | {f.right}/{f.runs} |")
    return "\n".join(lines) + "\n"
