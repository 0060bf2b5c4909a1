"""`woody sweep`: the paper's drop-test grid (meshes x k x line speed), headless, on Dask, resumable.

One run = the same mesh in every lane at one stiffness k and speed
(:func:`woody_experiments.experiment.evaluate_run`); it yields one row per lane
(fillet). Top-down columns (phi, hu_term, solidity_term) come from every lane,
side-view columns (nmdm, mdm, be) from the centre lane the side camera
watches, empty elsewhere. The runs go to a Dask cluster (:mod:`woody_experiments.cluster`:
an embedded LocalCluster, or ``--scheduler``). Only this process writes
``runs.csv``: each batch of finished runs replaces the file atomically, so a
killed or interrupted sweep leaves a valid file and loses at most the runs in
flight; a rerun skips every run whose rows are all there, whichever cluster
computed them (a run with missing lane rows is redone). At the end
``results.md`` and the plots are (re)built from the whole CSV.
With ``--traces`` every run also writes its lanes' Φ windows frame by frame
(:mod:`woody_experiments.traces`), and a run counts as done only with its trace.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
import time
from pathlib import Path

from woody_common.calibration import ENV_VAR, resolve_calibration, resolved_calibration
from woody_common.line import LANE_PITCH_M, check_lane_pitch
from woody_experiments import cluster, runs_csv, sweep, sweep_report, traces
from woody_experiments.conditions import SWEEP_CONDITIONS, TIDY
from woody_experiments.experiment import RunSpec
from woody_experiments.mesh_sets import DEFAULT_MESHES, load_meshes
from woody_experiments.run_report import uncalibrated_speed_note
from woody_sim.line_world import PAPER_PHYSICS, PhysicsConfig
from woody_sim.sensor_model import PRESETS
from woody_tools import arguments
from woody_vision.shape_score import W1, W2


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--meshes", default=DEFAULT_MESHES,
                        help="mesh set: builtin, generated:N[:SEED], a folder or file; comma-combinable "
                             f"(default {DEFAULT_MESHES})")
    parser.add_argument("--k", type=arguments.STIFFNESSES, default=list(sweep.DEFAULT_K),
                        help="hinge stiffnesses, comma-separated (default: union of the paper's top-down "
                             "0..100 and side-view 0,10,100,200,400)")
    parser.add_argument("--speeds", type=arguments.LINE_SPEEDS, default=list(sweep.DEFAULT_SPEEDS),
                        help="line speeds in FPM (default 100,130)")
    parser.add_argument("--lanes", type=int, default=3,
                        help="identical fillets side by side per run: one simulated chain, seen in every lane "
                             "(default 3)")
    parser.add_argument("--out", default="sweep-out", help="output folder (runs.csv, results.md, *.png)")
    parser.add_argument("--calibration", default=None, metavar="FILE",
                        help=f"calibration file the runs and the report use (default ${ENV_VAR}, else the installed "
                             "config/calibration.yaml)")
    parser.add_argument("--mass", type=arguments.POSITIVE_NUMBER, default=None,
                        help="total chain mass M in kg (default: the calibration's)")
    parser.add_argument("--sensor", default="ideal", choices=sorted(PRESETS),
                        help="top camera error model (docs/sensors.md); use its own --out; default ideal")
    arguments.add_top_camera(parser, "a file's error model is --sensor's; one camera per --out folder")
    arguments.add_yaw_sd(parser, "one setting per --out folder")
    parser.add_argument("--lane-pitch", type=float, default=LANE_PITCH_M, metavar="M",
                        help=f"distance between lane centres (default {LANE_PITCH_M:g} m; one setting per --out "
                             "folder)")
    parser.add_argument("--speed-change", type=arguments.SPEED_CHANGE, default=None, metavar="FPM@SECONDS",
                        help="the belt changes to FPM at SECONDS of sim time in every run (one setting per --out "
                             "folder)")
    parser.add_argument("--conditions", type=arguments.CONDITIONS, default=[TIDY],
                        help="how fillets lie, comma-separated: " + ", ".join(SWEEP_CONDITIONS) + " (default tidy; "
                             "docs/results.md, 'The messy line')")
    parser.add_argument("--traces", action="store_true",
                        help="also write Φ, Hu and solidity terms of every window frame per fillet: traces.csv and "
                             "traces/<mesh>_<speed>fpm.png (runs already done without a trace are redone)")
    parser.add_argument("--no-side", action="store_true", help="skip the side view (top-down Φ only)")
    parser.add_argument("--no-report", action="store_true", help="only run; do not rebuild results.md and plots")
    parser.add_argument("--docs", default=None, metavar="DIR",
                        help="also write results.md to DIR/results.md and the plots to DIR/results/ (e.g. docs)")
    cluster.add_arguments(parser, jobs_default=cluster.default_jobs())


def _geometry_problem(args: argparse.Namespace) -> str:
    """What is wrong with --lane-pitch or --top-camera ('' when nothing); a camera file is made absolute, since
    the workers read the same file."""
    try:
        check_lane_pitch(args.lanes, args.lane_pitch)
    except ValueError as exc:
        return f"--lane-pitch: {exc}"
    return arguments.top_camera_problem(args)


def run(args: argparse.Namespace) -> int:
    if args.lanes < 1 or args.jobs < 1 or args.scaling_probe < 0:
        print("woody sweep: --lanes and --jobs must be >= 1, --scaling-probe >= 0", file=sys.stderr)
        return 2
    problem = _geometry_problem(args)
    if problem:
        print(f"woody sweep: {problem}", file=sys.stderr)
        return 2
    line = {"lane_pitch_m": args.lane_pitch}
    if args.speed_change:
        line.update(speed_change_fpm=args.speed_change[0], speed_change_at_s=args.speed_change[1])
        args.speed_change = "{:g}@{:g}".format(*args.speed_change)  # as the folder's settings record it
    try:
        calibration_path = str(resolve_calibration(args.calibration).absolute())  # workers read the same file
        calibration = resolved_calibration(calibration_path)
        meshes = load_meshes(args.meshes, "woody sweep")
    except ValueError as exc:
        print(f"woody sweep: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out)  # made only once nothing refuses the sweep
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # a file of that name, a read-only place
        print(f"woody sweep: --out {out}: cannot make the folder ({exc.strerror})", file=sys.stderr)
        return 2
    mass = float(args.mass) if args.mass is not None else calibration.total_mass_kg
    names = list(meshes)
    csv_path = out / runs_csv.FILE_NAME
    mismatch = _folder_mismatch(out / sweep.META_FILE, args)
    if mismatch:
        print(f"woody sweep: {out} holds runs with {mismatch}", file=sys.stderr)
        return 2
    done, runs_file = sweep.completed_runs(csv_path, args.lanes, out if args.traces else None)
    runs = sweep.plan(names, args.k, args.speeds, args.lanes, mass, side=not args.no_side, top_camera=args.top_camera,
                      sensor=args.sensor, yaw_sd=args.yaw_sd, conditions=tuple(args.conditions),
                      calibration=calibration_path, line=line)
    todo = [r for r in runs if runs_csv.run_key(r.mesh, r.k, r.speed_fpm, mass, r.condition) not in done]
    where = args.scheduler or f"a local Dask cluster of {min(args.jobs, max(1, len(todo)))} workers"
    print(f"woody sweep: {len(names)} meshes x {len(args.k)} k x {len(args.speeds)} speeds x "
          f"{len(args.conditions)} conditions = {len(runs)} runs "
          f"({len(runs) - len(todo)} already in {csv_path}, {len(todo)} to go), {args.lanes} lanes, "
          f"M = {mass:g} kg, top camera {args.top_camera}, on {where}", file=sys.stderr)
    for fpm in args.speeds:
        note = uncalibrated_speed_note(fpm, calibration.speed_range_fpm)
        if note:
            print(f"woody sweep: {note} (the report counts them unscored)", file=sys.stderr)
    failed = _evaluate_todo(args, todo, meshes, runs_file)
    if failed is None:
        return 2
    meta = _update_meta(out / sweep.META_FILE, failed, args, len(names), mass)
    if not args.no_report:
        md = sweep_report.build(out, meta, docs=Path(args.docs) if args.docs else None,
                                calibration=calibration)
        print(f"woody sweep: wrote {md}", file=sys.stderr)
    if args.traces:
        _report_traces(out, calibration.phi_threshold)
    return 1 if failed.failed else 0


def _report_traces(out: Path, threshold: float) -> None:
    rows = traces.join(out)
    plots = traces.plot(out, rows, W1, W2, threshold)
    print(f"woody sweep: wrote {out / traces.TRACE_CSV} ({len(rows)} frames) and {len(plots)} trace plots in "
          f"{out / traces.TRACE_DIR}", file=sys.stderr)


FOLDER_SETTINGS = {"top_camera": "default", "yaw_sd": 0.0, "lane_pitch": LANE_PITCH_M, "speed_change": None,
                   "physics": PhysicsConfig(**PAPER_PHYSICS).resolution}
"""Settings all the runs in one --out folder share (runs.csv does not repeat them per row), with the value a folder
that does not record one was made with."""
SETTING_NAMES = {"physics": "the physics"}
"""How a refusal names a folder setting that no option sets (the others by their option)."""


def _folder_settings(args: argparse.Namespace) -> dict:
    """This sweep's value of every FOLDER_SETTINGS entry (the physics is PhysicsConfig's default: no option sets
    it)."""
    return {"top_camera": args.top_camera, "yaw_sd": args.yaw_sd, "lane_pitch": args.lane_pitch,
            "speed_change": args.speed_change, "physics": PhysicsConfig().resolution}


def _folder_mismatch(meta_path: Path, args: argparse.Namespace) -> str | None:
    """'--setting old; use another --out for --setting new' if this sweep's setting differs from the runs already
    in the folder, else None."""
    if not meta_path.exists():
        return None
    invocations = json.loads(meta_path.read_text()).get("invocations", [])
    for name, now in _folder_settings(args).items():
        before = {i.get(name, FOLDER_SETTINGS[name]) for i in invocations}
        flag = SETTING_NAMES.get(name, "--" + name.replace("_", "-"))
        if len(before) == 1 and now not in before:
            return f"{flag} {before.pop()}; use another --out for {flag} {now}"
    return None


def _evaluate_todo(args: argparse.Namespace, todo: list[RunSpec], meshes: dict,
                   runs_file: runs_csv.RunsFile) -> cluster.Throughput | None:
    """Run the missing runs on the cluster; None (after one line on stderr) when the cluster cannot be reached."""
    if not todo:
        return cluster.Throughput()
    def save(rows: list[dict]) -> None:
        runs_file.append(rows)
        if args.traces:
            traces.write_runs(Path(args.out), rows)

    try:
        with cluster.connect(args.scheduler, min(args.jobs, len(todo)), "woody sweep") as client:
            stats = cluster.run_tasks(client, sweep.run_rows, cluster.probe_order(todo, args.scaling_probe), meshes,
                                      save, "sweep", probe=args.scaling_probe)
            print(f"woody sweep: {cluster.describe_workers(client)}", file=sys.stderr)
    except cluster.ClusterUnavailable as exc:
        print(f"woody sweep: {exc}", file=sys.stderr)
        return None
    print(f"woody sweep: {stats.summary()}", file=sys.stderr)
    for line in stats.failed:
        print(f"woody sweep: not computed (rerun to retry): {line}", file=sys.stderr)
    return stats


def _update_meta(path: Path, stats: cluster.Throughput, args: argparse.Namespace, n_meshes: int,
                 mass: float) -> dict:
    meta = json.loads(path.read_text()) if path.exists() else {"invocations": []}
    if stats.evaluations:
        meta["invocations"].append({
            "command": ("woody " + " ".join(shlex.quote(a) for a in sys.argv[1:]))
            if Path(sys.argv[0]).name == "woody" else "woody " + " ".join(shlex.quote(a) for a in _argv(args)),
            "evaluations": stats.evaluations, "wall_s": round(stats.wall_s, 2), "jobs": stats.workers,
            "cores": os.cpu_count(), "scheduler": args.scheduler or "local", **stats.as_meta(),
            "meshes": args.meshes, "n_meshes": n_meshes, "mass": mass, "finished": time.strftime("%Y-%m-%d %H:%M:%S"),
            **_folder_settings(args),
        })
    meta["evaluations"] = sum(i["evaluations"] for i in meta["invocations"])
    meta["wall_s"] = sum(i["wall_s"] for i in meta["invocations"])
    path.write_text(json.dumps(meta, indent=2))
    return meta


def _argv(args: argparse.Namespace) -> list[str]:
    out = ["sweep", "--meshes", args.meshes, "--k", ",".join(f"{k:g}" for k in args.k),
           "--speeds", ",".join(f"{s:g}" for s in args.speeds), "--lanes", str(args.lanes),
           "--jobs", str(args.jobs), "--out", str(args.out)]
    if args.scheduler:
        out += ["--scheduler", args.scheduler]
    if args.calibration:
        out += ["--calibration", str(args.calibration)]
    if args.mass is not None:
        out += ["--mass", f"{args.mass:g}"]
    if args.top_camera != "default":
        out += ["--top-camera", args.top_camera]
    if args.traces:
        out.append("--traces")
    if args.sensor != "ideal":
        out += ["--sensor", args.sensor]
    if args.yaw_sd:
        out += ["--yaw-sd", f"{args.yaw_sd:g}"]
    if args.conditions != [TIDY]:
        out += ["--conditions", ",".join(args.conditions)]
    if args.lane_pitch != LANE_PITCH_M:
        out += ["--lane-pitch", f"{args.lane_pitch:g}"]
    if args.speed_change:
        out += ["--speed-change", args.speed_change]
    return out
