"""`woody calibrate`: tune the total chain mass M and the Φ decision threshold, then make them the defaults.

1. Mass. The paper tuned M so the simulated ΔNMDM(k=100 − k=0) at 100 FPM
   matches the physical study (≈ 0.25) with NMDM(k=0) near the normal
   fillets' 0.41 ± 0.10. Here: side view only (one lane, no top render),
   k ∈ {0, 100}, 100 FPM, a few calibration meshes; a coarse geometric grid of
   M, then a few finer steps around the best, minimising
   |ΔNMDM − 0.25| + distance of NMDM(k=0) outside 0.42–0.62.
2. Threshold. With the chosen M: top-down runs of the calibration meshes at
   k ∈ {0, 100} at both speeds, three lanes; the Φ cut that maximises the
   balanced accuracy of normal (k=0) vs severe (k=100) pooled over speeds and
   lanes. Classification is then reported on a DISJOINT test mesh set
   (different generated seeds), per speed and lane.

Unless ``--dry-run``, the two values are written into the constants that are
the defaults everywhere (the nodes, `woody run`, `woody sweep`):
``woody_sim.fillet_model.DEFAULT_TOTAL_MASS`` and
``woody_vision.grading.DEFAULT_PHI_THRESHOLD`` (the source lines are
rewritten; the editable install makes that effective at once). The search
log goes to ``--out``/calibration.json and calibration.md.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
import time
from pathlib import Path

import numpy as np

from woody_sim.fillet_model import MIN_STABLE_MASS
from woody_tools import cluster
from woody_tools.experiment import RunSpec

CALIBRATION_MESHES = "generated:8:9"
"""Calibration set (generated seeds 90000-90007); the sweep's default meshes (builtin, seeds 0-2 and 10000+) are disjoint."""
TEST_MESHES = "generated:8:8"
"""Disjoint held-out set for the threshold's classification report (seeds 80000-80007)."""
TARGET_DELTA = 0.25
DELTA_RANGE = (0.20, 0.32)
NORMAL_RANGE = (0.42, 0.62)
COARSE_MASSES = (10.0, 20.0, 40.0, 80.0, 160.0)
"""From MIN_STABLE_MASS up: lighter chains blow up at the belt edge (fillet_model.MIN_STABLE_MASS)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--meshes", default=CALIBRATION_MESHES, help=f"calibration meshes (default {CALIBRATION_MESHES})")
    parser.add_argument("--mass-meshes", type=int, default=4,
                        help="how many of the calibration meshes the mass search uses (default 4)")
    parser.add_argument("--test-meshes", default=TEST_MESHES,
                        help=f"held-out meshes for the threshold report, disjoint from --meshes (default {TEST_MESHES})")
    parser.add_argument("--masses", default=",".join(f"{m:g}" for m in COARSE_MASSES),
                        help="coarse grid of total masses M (kg) to try")
    parser.add_argument("--refine", type=int, default=2, help="refinement rounds around the best mass (default 2)")
    parser.add_argument("--mass", type=float, default=None, help="skip the mass search and use this M")
    parser.add_argument("--skip-threshold", action="store_true", help="calibrate the mass only")
    parser.add_argument("--out", default="calibration-out", help="folder for calibration.json / calibration.md")
    parser.add_argument("--dry-run", action="store_true", help="print the results, do not change the defaults")
    cluster.add_arguments(parser, jobs_default=None, probe=False)


def _evaluate(runs: list[RunSpec], mesh_spec: str, client, desc: str) -> list[dict]:
    """The runs' rows, evaluated on the Dask cluster exactly like `woody sweep` evaluates its grid."""
    from woody_tools import sweep

    rows: list[dict] = []
    stats = cluster.run_tasks(client, sweep._work, runs, sweep._load_meshes(mesh_spec), rows.extend, desc)
    for line in stats.failed:
        print(f"woody calibrate: not computed: {line}", file=sys.stderr)
    return rows


def mass_objective(nmdm0: float, nmdm100: float) -> float:
    """|ΔNMDM − 0.25| plus how far NMDM(k=0) lies outside 0.42–0.62 (0 inside)."""
    if not (math.isfinite(nmdm0) and math.isfinite(nmdm100)):
        return math.inf
    outside = max(0.0, NORMAL_RANGE[0] - nmdm0, nmdm0 - NORMAL_RANGE[1])
    return abs(nmdm100 - nmdm0 - TARGET_DELTA) + outside


def _side_point(mass: float, names: list[str], spec: str, client) -> dict:
    runs = [RunSpec(n, k, 100.0, lanes=1, mass=mass, top=False) for n in names for k in (0.0, 100.0)]
    rows = _evaluate(runs, spec, client, f"M={mass:g}")
    n0 = [r["nmdm"] for r in rows if r["k"] == 0.0 and math.isfinite(r.get("nmdm", math.nan))]
    n100 = [r["nmdm"] for r in rows if r["k"] == 100.0 and math.isfinite(r.get("nmdm", math.nan))]
    m0 = float(np.mean(n0)) if n0 else math.nan
    m100 = float(np.mean(n100)) if n100 else math.nan
    point = {"mass": mass, "nmdm_k0": m0, "nmdm_k100": m100, "delta": m100 - m0,
             "objective": mass_objective(m0, m100), "n": [len(n0), len(n100)]}
    print(f"  M = {mass:7.2f} kg: NMDM(k=0) {m0:.3f}, NMDM(k=100) {m100:.3f}, Δ {m100 - m0:+.3f}, "
          f"objective {point['objective']:.3f}", file=sys.stderr)
    return point


def search_mass(names: list[str], spec: str, masses: list[float], refine: int, client) -> tuple[float, list[dict]]:
    points = [_side_point(m, names, spec, client) for m in masses]
    for _ in range(refine):
        ordered = sorted(points, key=lambda p: p["mass"])
        best = min(range(len(ordered)), key=lambda i: ordered[i]["objective"])
        new = []
        for j in (best - 1, best + 1):  # geometric midpoints towards both neighbours
            if 0 <= j < len(ordered):
                new.append(max(MIN_STABLE_MASS, math.sqrt(ordered[best]["mass"] * ordered[j]["mass"])))
        points += [_side_point(round(m, 2), names, spec, client) for m in new]
    best = min(points, key=lambda p: p["objective"])
    return float(best["mass"]), sorted(points, key=lambda p: p["mass"])


def _phi_split(rows: list[dict]) -> tuple[list[float], list[float]]:
    ok = [r for r in rows if r.get("status") == "scored" and math.isfinite(r.get("phi", math.nan))]
    return [r["phi"] for r in ok if r["k"] == 0.0], [r["phi"] for r in ok if r["k"] == 100.0]


def write_default(path: Path, name: str, value: float) -> None:
    """Rewrite ``NAME = <number>`` in a module source file."""
    text = path.read_text()
    new, count = re.subn(rf"^{name} = [0-9.eE+-]+$", f"{name} = {value:g}", text, count=1, flags=re.M)
    if count != 1:
        raise RuntimeError(f"{path}: no line '{name} = <number>' to update")
    path.write_text(new)


def run(args: argparse.Namespace) -> int:
    jobs = args.jobs or cluster.default_jobs()
    try:
        with cluster.connect(args.scheduler, jobs, "woody calibrate") as client:
            return _calibrate(args, client)
    except cluster.ClusterUnavailable as exc:
        print(f"woody calibrate: {exc}", file=sys.stderr)
        return 2


def _calibrate(args: argparse.Namespace, client) -> int:
    from woody_sim import fillet_model
    from woody_tools import results, sweep
    from woody_vision import grading

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cal_names = list(sweep._load_meshes(args.meshes))
    test_names = list(sweep._load_meshes(args.test_meshes))
    overlap = set(cal_names) & set(test_names)
    if overlap:
        print(f"woody calibrate: test meshes overlap the calibration meshes: {sorted(overlap)}", file=sys.stderr)
        return 2
    if args.mass is not None and args.mass < MIN_STABLE_MASS:
        print(f"woody calibrate: --mass {args.mass:g} is below the stable minimum {MIN_STABLE_MASS:g} kg "
              "(the chain blows up at the belt edge)", file=sys.stderr)
        return 2
    report: dict = {"calibration_meshes": args.meshes, "test_meshes": args.test_meshes, "started": time.ctime()}
    t0 = time.perf_counter()
    if args.mass is None:
        masses = [float(m) for m in args.masses.split(",") if m.strip()]
        unstable = [m for m in masses if m < MIN_STABLE_MASS]
        if unstable:
            print(f"woody calibrate: masses {unstable} are below the stable minimum {MIN_STABLE_MASS:g} kg "
                  "(the chain blows up at the belt edge)", file=sys.stderr)
            return 2
        names = cal_names[: max(1, args.mass_meshes)]
        print(f"woody calibrate: mass search on {len(names)} meshes, side view, k 0/100, 100 FPM", file=sys.stderr)
        mass, points = search_mass(names, args.meshes, masses, args.refine, client)
        report["mass_search"] = points
        best = next(p for p in points if p["mass"] == mass)
        report["mass"] = mass
        report["mass_check"] = {
            "delta": best["delta"], "nmdm_k0": best["nmdm_k0"],
            "delta_in_range": DELTA_RANGE[0] <= best["delta"] <= DELTA_RANGE[1],
            "nmdm_k0_in_range": NORMAL_RANGE[0] <= best["nmdm_k0"] <= NORMAL_RANGE[1]}
        print(f"woody calibrate: chosen M = {mass:g} kg (ΔNMDM {best['delta']:.3f}, NMDM(k=0) {best['nmdm_k0']:.3f})")
    else:
        mass = float(args.mass)
        report["mass"] = mass
    if not args.skip_threshold:
        runs = [RunSpec(n, k, s, lanes=3, mass=mass, side=False) for n in cal_names for s in (100.0, 130.0)
                for k in (0.0, 100.0)]
        cal_rows = _evaluate(runs, args.meshes, client, "threshold (calibration set)")
        normal, severe = _phi_split(cal_rows)
        threshold, bacc = results.best_threshold(normal, severe)
        threshold = round(threshold, 2)
        report.update(threshold=threshold, calibration_balanced_accuracy=bacc,
                      calibration_auc=results.roc(normal, severe)[2], calibration_n=[len(normal), len(severe)])
        print(f"woody calibrate: Φ threshold = {threshold:g} (balanced accuracy {bacc * 100:.1f} % on "
              f"{len(normal)} normal / {len(severe)} severe calibration fillets)")
        runs = [RunSpec(n, k, s, lanes=3, mass=mass, side=False) for n in test_names for s in (100.0, 130.0)
                for k in (0.0, 100.0)]
        test_rows = _evaluate(runs, args.test_meshes, client, "held-out test set")
        per = []
        for speed in (100.0, 130.0):
            for lane in (None, 0, 1, 2):
                sel = [r for r in test_rows if r["speed_fpm"] == speed and (lane is None or r["lane"] == lane)]
                n, s = _phi_split(sel)
                acc, right, total = results.accuracy(n, s, threshold)
                per.append({"speed_fpm": speed, "lane": "all" if lane is None else lane, "accuracy": acc,
                            "right": right, "total": total, "auc": results.roc(n, s)[2]})
                print(f"  held-out {speed:g} FPM lane {'all' if lane is None else lane}: accuracy {acc * 100:.1f} % "
                      f"({right}/{total}), AUC {per[-1]['auc']:.3f}")
        report["test"] = per
    report["wall_s"] = round(time.perf_counter() - t0, 1)
    (out / "calibration.json").write_text(json.dumps(report, indent=2))
    _write_md(out / "calibration.md", report)
    if not args.dry_run:
        write_default(Path(fillet_model.__file__), "DEFAULT_TOTAL_MASS", mass)
        print(f"woody calibrate: wrote DEFAULT_TOTAL_MASS = {mass:g} to {fillet_model.__file__}")
        if "threshold" in report:
            write_default(Path(grading.__file__), "DEFAULT_PHI_THRESHOLD", report["threshold"])
            print(f"woody calibrate: wrote DEFAULT_PHI_THRESHOLD = {report['threshold']:g} to {grading.__file__}")
    return 0


def _write_md(path: Path, report: dict) -> None:
    L = ["# Calibration\n", f"Total mass M = **{report['mass']:g} kg**; Φ threshold = "
         f"**{report.get('threshold', 'n/a')}**; wall {report.get('wall_s', 0) / 60:.1f} min.\n"]
    if "mass_search" in report:
        L += ["| M (kg) | NMDM k=0 | NMDM k=100 | ΔNMDM | objective |", "|---|---|---|---|---|"]
        L += [f"| {p['mass']:g} | {p['nmdm_k0']:.3f} | {p['nmdm_k100']:.3f} | {p['delta']:.3f} | {p['objective']:.3f} |"
              for p in report["mass_search"]]
    if "test" in report:
        L += ["", f"Threshold from `{report['calibration_meshes']}` (balanced accuracy "
              f"{report['calibration_balanced_accuracy'] * 100:.1f} %, AUC {report['calibration_auc']:.3f}); "
              f"held-out `{report['test_meshes']}`:\n", "| FPM | lane | accuracy | right/total | AUC |", "|---|---|---|---|---|"]
        L += [f"| {t['speed_fpm']:g} | {t['lane']} | {t['accuracy'] * 100:.1f} % | {t['right']}/{t['total']} | {t['auc']:.3f} |"
              for t in report["test"]]
    path.write_text("\n".join(L) + "\n")
