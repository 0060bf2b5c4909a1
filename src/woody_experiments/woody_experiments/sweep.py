"""The drop-test grid of `woody sweep`: the paper's k and speeds, the runs of a grid, and its ``runs.csv``.

One run = the same mesh in every lane at one stiffness k and speed
(:func:`woody_experiments.experiment.evaluate_run`); it yields one row per lane
(fillet). Top-down columns (phi, hu_term, solidity_term) come from every lane,
side-view columns (nmdm, mdm, be) from the centre lane the side camera
watches, empty elsewhere. Only the client writes ``runs.csv`` (`RunsFile`):
each batch of finished runs replaces the file atomically, so a killed or
interrupted sweep leaves a valid file and loses at most the runs in flight;
`completed_runs` tells a rerun which runs are done (a run with missing lane
rows, or without its trace when traces are asked for, is redone).
"""

from __future__ import annotations

import math
from pathlib import Path

from woody_common.line import PAPER_SPEEDS_FPM
from woody_experiments.conditions import TIDY
from woody_experiments.experiment import RunSpec, evaluate_run
from woody_experiments.runs_csv import FILE_NAME, RunsFile, read_runs, row_key
from woody_experiments.traces import run_file
from woody_sim.meshes import mesh_yaw

TOP_K = (0.0, 20.0, 40.0, 60.0, 80.0, 100.0)
"""Paper, top-down view (Table tdv_results)."""
SIDE_K = (0.0, 10.0, 100.0, 200.0, 400.0)
"""Paper, side view (Table sv_results)."""
DEFAULT_K = tuple(sorted(set(TOP_K) | set(SIDE_K)))
DEFAULT_SPEEDS = PAPER_SPEEDS_FPM
META_FILE = "sweep_meta.json"
CSV_FILE = FILE_NAME


def completed_runs(path: Path, lanes: int, traced: Path | None = None) -> tuple[set[tuple], RunsFile]:
    """Keys of runs with all their lane rows in the CSV (and, with ``traced`` = the sweep folder, their trace
    file), and the file to append to without the other runs' rows (they are redone cleanly)."""
    by_run: dict[tuple, list[dict]] = {}
    for row in read_runs(path):
        if all(math.isfinite(row[c]) for c in ("mass", "k", "speed_fpm")):
            by_run.setdefault(row_key(row), []).append(row)
    done = {key for key, rs in by_run.items() if {r["lane"] for r in rs} >= set(range(lanes))}
    if traced is not None:
        done = {key for key in done if run_file(traced, *key).exists()}
    keep = [r for key, rs in by_run.items() if key in done for r in rs]
    return done, RunsFile(path, keep)


# ---------------------------------------------------------------- evaluation

def run_rows(run: RunSpec, mesh) -> list[dict]:
    """One run's rows, on a worker; an evaluation error becomes error rows so one broken mesh cannot stop a sweep."""
    try:
        return evaluate_run(run, mesh)
    except Exception as exc:
        return [{"mesh": run.mesh, "k": run.k, "speed_fpm": run.speed_fpm, "condition": run.condition, "lane": lane,
                 "mass": run.mass, "status": "error", "reason": f"{type(exc).__name__}: {exc}"}
                for lane in range(run.lanes)]


def plan(mesh_names: list[str], ks: list[float], speeds: list[float], lanes: int, mass: float,
         side: bool = True, top_camera: str = "default", sensor: str = "ideal", yaw_sd: float = 0.0,
         conditions: tuple[str, ...] = (TIDY,), calibration: str | None = None, line: dict | None = None
         ) -> list[RunSpec]:
    """Runs ordered so that partial results already span the grid (k, speed and condition vary fastest).

    The side view is measured on the tidy line only: the paper's side-view tables are about it. ``line``
    sets RunSpec's lane pitch and speed change for every run.
    """
    return [RunSpec(name, float(k), float(speed), lanes=lanes, mass=float(mass), side=side and condition == TIDY,
                    top_camera=top_camera, sensor=sensor, yaw_deg=mesh_yaw(name, yaw_sd), condition=condition,
                    calibration=calibration, **(line or {}))
            for name in mesh_names for condition in conditions for speed in speeds for k in ks]
