"""What `woody calibrate` does: fit the chain physics to the paper's side view, choose the Φ threshold, write the YAML.

1. Physics. Total mass M, hinge damper c and the drive's friction cap mu are
   fitted together against the paper's side-view table (NMDM at k = 0, 10,
   100, 200, 400, at 100 and 130 FPM) on a few calibration meshes, one lane,
   side camera only (:mod:`woody_experiments.physics_fit`): a grid over the given
   values, best by RMS NMDM error plus the distance of ΔNMDM(k=100 − k=0) and
   of the k = 0 speed gain from their bands.
2. Threshold. With the fitted physics: top-down runs of the calibration meshes
   at k ∈ {0, 100} at both speeds, three lanes; the Φ cut that maximises the
   balanced accuracy of normal (k=0) vs severe (k=100). Classification is then
   reported on a DISJOINT test mesh set, per speed and lane. The same rows
   give the top-view speed effect (Φ at 130 vs 100 FPM).

3. Line cuts. The line grades ``line_phi`` (woody_vision.shape_score)
   against cuts that follow the measured speed and leading end
   (woody_vision.grading.Cut). They are fitted on the calibration meshes on
   the tidy and the messy line at 90-140 FPM and k ∈ {0, 10, 20, 40, 100}
   (:mod:`woody_experiments.line_grade`: the reject cut k = 0 vs 100, the
   grade's normal/moderate and moderate/severe cuts), and reported on the
   disjoint test meshes per condition and speed.

Unless ``--dry-run`` the values and their provenance (command, date, mesh
sets, targets, achieved figures) are written to ``config/calibration.yaml``
(:mod:`woody_common.calibration`), which line_sim, the grader, `woody run`
and `woody sweep` load. The search log goes to ``--out``/calibration.json and
calibration.md.

``--yaw-sd`` lays every fillet of every step turned on the belt as `woody
sweep --yaw-sd` and `woody run --yaw-sd` do, so a threshold can be chosen on
the fillets it will grade; the spread is recorded in the provenance.

``--loo`` instead checks the threshold procedure itself on the reference
(real) meshes: top-down runs at k ∈ {0, 100}, both speeds, three lanes; per
speed, each mesh is held out once, the threshold is chosen on the others and
scored on it, one vote per run (:mod:`woody_experiments.evaluation`). It writes no
calibration.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
import time
from pathlib import Path

import numpy as np

from woody_common.calibration import (
    LIST_FIELDS,
    Calibration,
    camera_name,
    resolve_calibration,
    resolved_calibration,
    write_calibration,
)
from woody_common.line import CLASS_K, NORMAL_K, PAPER_SPEEDS_FPM, SEVERE_K
from woody_experiments import cluster, evaluation, line_grade, physics_fit
from woody_experiments.experiment import RunSpec
from woody_experiments.mesh_sets import CALIBRATION_MESHES, LOO_MESHES, load_meshes
from woody_experiments.statistics import accuracy, best_threshold, roc
from woody_experiments.sweep import run_rows
from woody_sim.meshes import mesh_yaw

SIDE_K = (0.0, 10.0, 100.0, 200.0, 400.0)
SPEEDS = PAPER_SPEEDS_FPM
LINE_SPEEDS = (90.0, 100.0, 115.0, 130.0, 140.0)
"""The line cuts are fitted over the speeds a line runs at, the paper's two among them."""
LINE_K = (0.0, 10.0, 20.0, 40.0, 100.0)
LINE_CONDITIONS = ("tidy", "turned", "blunt", "messy", "wide")
"""The line cuts are fitted over every way a fillet lies, each on its own and together, and over every turn the
line allows (wide): the messy line's turns are a normal draw, so a stiff fillet both blunt end first and turned
past 25 deg was scarce, and a cut fitted without it was extrapolated exactly where such a fillet lies."""
PROGRAM = "woody calibrate"
"""Prefixes the lines its mesh sets' skipped and converted files are named in."""


def _evaluate(runs: list[RunSpec], mesh_spec: str, client, desc: str) -> list[dict]:
    """The runs' rows, evaluated on the Dask cluster exactly like `woody sweep` evaluates its grid."""
    rows: list[dict] = []
    stats = cluster.run_tasks(client, run_rows, runs, load_meshes(mesh_spec, PROGRAM), rows.extend, desc)
    for line in stats.failed:
        print(f"woody calibrate: not computed: {line}", file=sys.stderr)
    return rows


def fit_physics(names: list[str], spec: str, args: argparse.Namespace, client) -> tuple[dict, list[dict]]:
    """Grid search of (M, c, mu) against the paper's side table; the best point's values and the log."""
    def evaluate(point: physics_fit.FitPoint) -> list[dict]:
        runs = [RunSpec(n, k, s, lanes=1, mass=point.mass, damping=point.damping,
                        friction_static=point.friction_static, top=False, yaw_deg=mesh_yaw(n, args.yaw_sd),
                        calibration=args.calibration)
                for n in names for s in SPEEDS for k in SIDE_K]
        return _evaluate(runs, spec, client, f"M={point.mass:g} c={point.damping:g} mu={point.friction_static:g}")

    def report(point, entry, score) -> None:
        print(f"  M {point.mass:g} kg, c {point.damping:g}, mu {point.friction_static:g}: objective {score:.3f}, "
              f"NMDM(k=0) {entry['nmdm_k0_100fpm']:.3f}, ΔNMDM {entry['delta_nmdm_100fpm']:.3f}, "
              f"k=0 speed gain {entry['nmdm_k0_speed_gain']:+.3f}", file=sys.stderr)

    points = physics_fit.grid(args.masses, args.dampings, args.frictions)
    best, log = physics_fit.search(points, evaluate, report)
    values = {"total_mass_kg": best.mass, "hinge_damping": best.damping, "friction_static": best.friction_static,
              "friction_dynamic": best.friction_dynamic}
    return values, log


def _phi_split(rows: list[dict]) -> tuple[list[float], list[float]]:
    ok = [r for r in rows if r.get("status") == "scored" and math.isfinite(r.get("phi", math.nan))]
    return [r["phi"] for r in ok if r["k"] == NORMAL_K], [r["phi"] for r in ok if r["k"] == SEVERE_K]


def choose_threshold(cal_names: list[str], test_names: list[str], physics: dict, args: argparse.Namespace,
                     client) -> dict:
    """Φ cut on the calibration meshes, its accuracy on the held-out ones, and the top-view speed effect."""
    def rows_for(names: list[str], spec: str, desc: str) -> list[dict]:
        runs = [RunSpec(n, k, s, lanes=3, mass=physics["total_mass_kg"], damping=physics["hinge_damping"],
                        friction_static=physics["friction_static"], side=False, yaw_deg=mesh_yaw(n, args.yaw_sd),
                        top_camera=args.top_camera, calibration=args.calibration)
                for n in names for s in SPEEDS for k in CLASS_K]
        return _evaluate(runs, spec, client, desc)

    cal_rows = rows_for(cal_names, args.meshes, "threshold (calibration set)")
    normal, severe = _phi_split(cal_rows)
    threshold, bacc = best_threshold(normal, severe)
    report = {"threshold": round(threshold, 2), "calibration_balanced_accuracy": bacc,
              "calibration_auc": roc(normal, severe)[2], "calibration_n": [len(normal), len(severe)],
              "top_speed_effect": _speed_effect(cal_rows)}
    print(f"woody calibrate: Φ threshold = {report['threshold']:g} (balanced accuracy {bacc * 100:.1f} % on "
          f"{len(normal)} normal / {len(severe)} severe calibration fillets)")
    report["test"] = _held_out(rows_for(test_names, args.test_meshes, "held-out test set"), report["threshold"])
    return report


def choose_line_cuts(cal_names: list[str], test_names: list[str], physics: dict, args: argparse.Namespace,
                     client) -> dict:
    """The line's three cuts on the calibration meshes, and their figures on the held-out ones."""
    def rows_for(names: list[str], spec: str, desc: str) -> list[dict]:
        """Rows of every lane of the widest line the camera sees: the cuts see each place across the belt a fillet
        is seen from."""
        runs = [RunSpec(n, k, s, lanes=args.lanes, mass=physics["total_mass_kg"], damping=physics["hinge_damping"],
                        friction_static=physics["friction_static"], side=False, condition=c,
                        top_camera=args.top_camera, calibration=args.calibration)
                for n in names for c in LINE_CONDITIONS for s in LINE_SPEEDS for k in LINE_K]
        return _evaluate(runs, spec, client, desc)

    cal_rows = rows_for(cal_names, args.meshes, "line cuts (calibration set)")
    rules = line_grade.fit_rules(cal_rows)
    fitted = line_grade.fitted_range(cal_rows)
    print(f"woody calibrate: fitted range {fitted.speed_min_mps:.3f}-{fitted.speed_max_mps:.3f} m/s, turns up to "
          f"{fitted.turn_max_deg:.1f} deg, bodies {fitted.length_min_m:.3f}-{fitted.length_max_m:.3f} m")
    cuts = {"line_threshold": rules.threshold,
            "severe_threshold": rules.severe_threshold}
    for name, cut in cuts.items():
        print(f"woody calibrate: {name} = {cut.base:.3g} at 100 FPM narrow end first, "
              f"x exp({cut.speed_slope:+.3g}/(m/s)), x exp({cut.blunt_offset:+.3g}) blunt end first")
    runs = line_grade.graded_runs(rows_for(test_names, args.test_meshes, "line cuts (held-out test set)"), rules,
                                  fitted)
    test = []
    for condition in LINE_CONDITIONS:
        for speed in LINE_SPEEDS:
            summary = line_grade.summarise([r for r in runs if r.condition == condition and r.speed_fpm == speed])
            test.append({"condition": condition, "speed_fpm": speed, "right": summary.right, "total": summary.total,
                         "severe_passed": summary.severe_passed, "auc": summary.auc,
                         "grade_right": summary.grade_right, "grade_total": summary.grade_total})
            print(f"  held-out {condition} {speed:g} FPM: {summary.right}/{summary.total} normal vs severe, "
                  f"{summary.severe_passed} severe graded normal, three classes {summary.grade_right}/"
                  f"{summary.grade_total}")
    return {"line_cuts": {name: cut.as_list() for name, cut in cuts.items()}, "fitted_range": fitted.as_list(),
            "line_test": test}


def _speed_effect(rows: list[dict]) -> dict:
    """Mean Φ per k at 100 and 130 FPM (the paper: every class lower at 130 FPM, k = 0 above all)."""
    out = {}
    for k in CLASS_K:
        means = [np.mean([r["phi"] for r in rows if r["k"] == k and r["speed_fpm"] == s and r.get("status") == "scored"
                          and math.isfinite(r["phi"])] or [math.nan]) for s in SPEEDS]
        out[f"phi_k{k:g}"] = {f"{s:g}fpm": float(m) for s, m in zip(SPEEDS, means)}
    return out


def _held_out(rows: list[dict], threshold: float) -> list[dict]:
    per = []
    for speed in SPEEDS:
        for lane in (None, 0, 1, 2):
            sel = [r for r in rows if r["speed_fpm"] == speed and (lane is None or r["lane"] == lane)]
            n, s = _phi_split(sel)
            acc, right, total = accuracy(n, s, threshold)
            per.append({"speed_fpm": speed, "lane": "all" if lane is None else lane, "accuracy": acc,
                        "right": right, "total": total, "auc": roc(n, s)[2]})
            print(f"  held-out {speed:g} FPM lane {per[-1]['lane']}: accuracy {acc * 100:.1f} % ({right}/{total}), "
                  f"AUC {per[-1]['auc']:.3f}")
    return per


PHYSICS_PROVENANCE = ("fit_meshes", "achieved_nmdm", "achieved_delta", "achieved_objective")
"""Provenance keys (or their beginnings) of the physics fit: kept from the current calibration by --skip-physics."""


def _provenance(args: argparse.Namespace, report: dict, current: dict) -> dict:
    """Flat key -> value record of how the calibration was made and what it reached; with ``--skip-physics`` the
    physics fit's record of the ``current`` calibration stays (its values do)."""
    out = {"command": "woody calibrate " + shlex.join(sys.argv[2:]), "date": time.strftime("%Y-%m-%d %H:%M:%S"),
           "calibration_meshes": args.meshes, "fit_meshes": report.get("fit_meshes", ""),
           "test_meshes": args.test_meshes, "yaw_sd_deg": args.yaw_sd, "top_camera": camera_name(args.top_camera),
           "lanes": args.lanes,
           "targets": "paper Table sv_results (NMDM at k 0/10/100/200/400, "
           "100 and 130 FPM); ΔNMDM(k=100-k=0) 0.20-0.32; NMDM(k=0) gain >= 0.05 at 130 FPM"}
    if args.skip_physics:
        out.update({k: v for k, v in current.items() if k.startswith(PHYSICS_PROVENANCE)})
    best = min(report.get("physics_fit", []), key=lambda e: e["objective"], default=None)
    if best is not None:
        out.update({f"achieved_{k}": round(v, 4) for k, v in best.items() if k.startswith(("nmdm", "delta"))})
        out["achieved_objective"] = round(best["objective"], 4)
    for t in report.get("test", []):
        if t["lane"] == "all":
            out[f"achieved_heldout_accuracy_{t['speed_fpm']:g}fpm"] = round(t["accuracy"], 4)
    line = report.get("line_test", [])
    if line:
        out["line_conditions"] = ",".join(LINE_CONDITIONS)
        out["line_speeds_fpm"] = ",".join(f"{s:g}" for s in LINE_SPEEDS)
        out["achieved_heldout_line_accuracy"] = round(sum(t["right"] for t in line) / sum(t["total"] for t in line), 4)
        out["achieved_heldout_line_severe_passed"] = sum(t["severe_passed"] for t in line)
        out["achieved_heldout_three_class_accuracy"] = round(
            sum(t["grade_right"] for t in line) / sum(t["grade_total"] for t in line), 4)
    return out


def mesh_specs(args: argparse.Namespace) -> list[str]:
    """The mesh sets the calibration evaluates (with ``args.loo``: the leave-one-out check's), defaults filled in."""
    if args.loo:
        return [args.meshes or LOO_MESHES]
    return [args.meshes or CALIBRATION_MESHES, args.test_meshes]


def calibrate(args: argparse.Namespace, client) -> int:
    """The whole calibration (or, with ``args.loo``, the leave-one-out check) on the Dask ``client``."""
    out = Path(args.out)
    args.calibration = str(resolve_calibration(args.calibration).absolute())  # the workers read the same file
    if args.loo:
        return run_loo(mesh_specs(args)[0], client, out, args.yaw_sd, args.calibration)
    args.meshes = mesh_specs(args)[0]
    try:
        cal_names = list(load_meshes(args.meshes, PROGRAM))
        test_names = list(load_meshes(args.test_meshes, PROGRAM))
    except ValueError as exc:  # a malformed spec or a missing path
        print(f"woody calibrate: {exc}", file=sys.stderr)
        return 2
    if set(cal_names) & set(test_names):
        overlap = sorted(set(cal_names) & set(test_names))
        print(f"woody calibrate: test meshes overlap the calibration meshes: {overlap}", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    try:
        current = resolved_calibration(args.calibration)
    except ValueError as exc:
        print(f"woody calibrate: {exc}", file=sys.stderr)
        return 2
    physics = {k: getattr(current, k)
               for k in ("total_mass_kg", "hinge_damping", "friction_static", "friction_dynamic")}
    report: dict = {"calibration_meshes": args.meshes, "test_meshes": args.test_meshes, "yaw_sd_deg": args.yaw_sd,
                    "started": time.ctime()}
    t0 = time.perf_counter()
    if not args.skip_physics:
        names = cal_names[: max(1, args.fit_meshes)]
        print(f"woody calibrate: physics fit on {len(names)} meshes, side view, k {SIDE_K}, {SPEEDS} FPM",
              file=sys.stderr)
        physics, report["physics_fit"] = fit_physics(names, args.meshes, args, client)
        report["fit_meshes"] = ",".join(names)
        print(f"woody calibrate: M = {physics['total_mass_kg']:g} kg, c = {physics['hinge_damping']:g}, "
              f"mu = {physics['friction_static']:g}")
    report["physics"] = physics
    threshold = current.phi_threshold
    cuts = {name: getattr(current, name) for name in LIST_FIELDS}
    if not args.skip_threshold:
        report.update(choose_threshold(cal_names, test_names, physics, args, client))
        report.update(choose_line_cuts(cal_names, test_names, physics, args, client))
        threshold, cuts = report["threshold"], {**report["line_cuts"], "fitted_range": report["fitted_range"]}
    report["wall_s"] = round(time.perf_counter() - t0, 1)
    (out / "calibration.json").write_text(json.dumps(report, indent=2))
    _write_md(out / "calibration.md", report)
    if not args.dry_run:
        provenance = _provenance(args, report, current.provenance)
        calibration = Calibration(**physics, phi_threshold=threshold, **cuts, provenance=provenance)
        path = write_calibration(calibration, args.calibration, header=CALIBRATION_HEADER)
        print(f"woody calibrate: wrote {path}")
    return 0


CALIBRATION_HEADER = """woody line calibration, written by `woody calibrate` (do not edit by hand; rerun it).
A ROS 2 parameters file: line_sim and grader load it (woody run passes --params-file);
woody sweep and woody calibrate read it through woody_common.calibration."""


def _write_md(path: Path, report: dict) -> None:
    physics = report["physics"]
    lines = ["# Calibration\n", f"M = **{physics['total_mass_kg']:g} kg**, c = **{physics['hinge_damping']:g}**, "
             f"mu = **{physics['friction_static']:g}**; Φ threshold = **{report.get('threshold', 'n/a')}**; "
             f"fillets turned by a yaw sd of {report['yaw_sd_deg']:g} deg; "
             f"wall {report.get('wall_s', 0) / 60:.1f} min.\n"]
    if "physics_fit" in report:
        lines += ["| M (kg) | c | mu | NMDM k=0 | ΔNMDM | k=0 speed gain | objective |",
                  "|---|---|---|---|---|---|---|"]
        lines += [f"| {p['mass']:g} | {p['damping']:g} | {p['friction_static']:g} | {p['nmdm_k0_100fpm']:.3f} | "
                  f"{p['delta_nmdm_100fpm']:.3f} | {p['nmdm_k0_speed_gain']:+.3f} | {p['objective']:.3f} |"
                  for p in report["physics_fit"]]
    if "test" in report:
        lines += ["", f"Threshold from `{report['calibration_meshes']}` (balanced accuracy "
                  f"{report['calibration_balanced_accuracy'] * 100:.1f} %, AUC {report['calibration_auc']:.3f}); "
                  f"held-out `{report['test_meshes']}`:\n", "| FPM | lane | accuracy | right/total | AUC |",
                  "|---|---|---|---|---|"]
        lines += [f"| {t['speed_fpm']:g} | {t['lane']} | {t['accuracy'] * 100:.1f} % | {t['right']}/{t['total']} | "
                  f"{t['auc']:.3f} |" for t in report["test"]]
    if "line_test" in report:
        lines += ["", "Line cuts [base, speed slope, blunt offset]: " + "; ".join(
            f"{name} {[round(v, 4) for v in cut]}" for name, cut in report["line_cuts"].items()),
            f"held-out `{report['test_meshes']}`, one vote per run:\n",
            "| condition | FPM | normal vs severe | severe graded normal | AUC | three classes |",
            "|---|---|---|---|---|---|"]
        lines += [f"| {t['condition']} | {t['speed_fpm']:g} | {t['right']}/{t['total']} | {t['severe_passed']} | "
                  f"{t['auc']:.3f} | {t['grade_right']}/{t['grade_total']} |" for t in report["line_test"]]
    path.write_text("\n".join(lines) + "\n")


def run_loo(spec: str, client, out: Path, yaw_sd: float = 0.0, calibration: str | None = None) -> int:
    """`woody calibrate --loo`: leave-one-mesh-out threshold check on the reference meshes of ``spec``."""
    try:
        names = [n for n in load_meshes(spec, PROGRAM) if evaluation.mesh_set(n) == evaluation.SET_REFERENCE]
    except ValueError as exc:
        print(f"woody calibrate: {exc}", file=sys.stderr)
        return 2
    if len(names) < 2:
        print(f"woody calibrate: --loo needs at least two reference (non-generated) meshes in '{spec}', got {names}",
              file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    mass = resolved_calibration(calibration).total_mass_kg
    runs = [RunSpec(n, k, s, lanes=3, mass=mass, side=False, yaw_deg=mesh_yaw(n, yaw_sd), calibration=calibration)
            for n in names
            for s in SPEEDS for k in CLASS_K]
    rows = _evaluate(runs, spec, client, f"leave-one-out ({len(names)} reference meshes)")
    units = evaluation.run_units(rows)
    report: dict = {"meshes": names, "mass": mass, "yaw_sd_deg": yaw_sd, "speeds": {}}
    lines = [f"# Leave-one-out over {len(names)} reference meshes (M = {mass:g} kg, yaw sd {yaw_sd:g} deg)\n"]
    for speed in SPEEDS:
        folds = evaluation.leave_one_out([u for u in units if u.speed_fpm == speed])
        total = evaluation.pooled(folds)
        report["speeds"][f"{speed:g}"] = {
            "folds": [{"held_out": f.held_out, "threshold": f.threshold, "train_balanced_accuracy":
                       f.train_balanced_accuracy, "right": f.test.right, "total": f.test.total} for f in folds],
            "right": total.right, "total": total.total, "accuracy": total.accuracy, "wilson95": total.interval}
        lines.append(f"{speed:g} FPM: {total.text()}")
        lines += [f"  held out {f.held_out}: threshold {f.threshold:.2f} from the others -> {f.test.text()}"
                  for f in folds]
    print("\n".join(lines))
    (out / "loo.json").write_text(json.dumps(report, indent=2))
    (out / "loo.md").write_text("\n".join(lines) + "\n")
    return 0
