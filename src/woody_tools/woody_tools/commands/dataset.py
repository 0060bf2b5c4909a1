"""`woody dataset`: labelled frames of a grid of runs (COCO instance segmentation and per-fillet sequences).

The grid and its options are `woody sweep`'s; the runs go to the same Dask
cluster (:mod:`woody_experiments.cluster`), and each worker writes its run's
frames into ``--out`` itself (with ``--scheduler``, the folder must be at the
same path on every worker). This process writes the index files once every
run is done: the COCO files per split, fillets.csv, splits.json and the
datasheet README.md (:mod:`woody_experiments.dataset`). A rerun into the same
folder skips the finished runs, and writes the same bytes.
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
import time
from collections import Counter
from pathlib import Path

from woody_common.calibration import resolve_calibration, resolved_calibration
from woody_experiments import cluster, dataset, sweep
from woody_experiments.conditions import SWEEP_CONDITIONS, TIDY
from woody_experiments.line_grade import GRADES
from woody_experiments.mesh_sets import DEFAULT_MESHES, load_meshes
from woody_sim.line_geometry import TOP_CAMERA_PRESETS
from woody_sim.sensor_model import PRESETS
from woody_tools import arguments
from woody_tools.benchmarks.suite import reference_ms

DEFAULT_K = (0.0, 20.0, 40.0, 100.0)
"""Normal, two moderate and a severe stiffness: every class of the grade."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", required=True, help="the data set folder (made; a rerun resumes it)")
    parser.add_argument("--meshes", default=DEFAULT_MESHES,
                        help=f"mesh set: builtin, generated:N[:SEED], a folder or file; comma-combinable "
                             f"(default {DEFAULT_MESHES}); the splits are by mesh")
    parser.add_argument("--k", type=arguments.STIFFNESSES, default=list(DEFAULT_K),
                        help="hinge stiffnesses, comma-separated (default 0,20,40,100: normal, moderate, severe)")
    parser.add_argument("--speeds", type=arguments.LINE_SPEEDS, default=list(sweep.DEFAULT_SPEEDS),
                        help="line speeds in FPM (default 100,130)")
    parser.add_argument("--conditions", type=arguments.CONDITIONS, default=[TIDY],
                        help="how fillets lie, comma-separated: " + ", ".join(SWEEP_CONDITIONS) + " (default tidy)")
    parser.add_argument("--lanes", type=int, default=3, help="fillets side by side per run (default 3)")
    parser.add_argument("--side", action="store_true",
                        help="also write the side camera's frames and masks (the watched lane)")
    parser.add_argument("--seed", type=int, default=0, help="draws the mesh splits (default 0)")
    parser.add_argument("--sensor", default="ideal", choices=sorted(PRESETS),
                        help="top camera error model of the colour and depth images (docs/sensors.md; default "
                             "ideal)")
    parser.add_argument("--top-camera", default="default", choices=sorted(TOP_CAMERA_PRESETS),
                        help="top camera geometry (default: 672x376 at 0.75 m)")
    cluster.add_arguments(parser, jobs_default=cluster.default_jobs(), probe=False)


SETTINGS = ("meshes", "k", "speeds", "conditions", "lanes", "side", "seed", "sensor", "top_camera")
"""The options that make a data set: a rerun into a folder must repeat them."""


def run(args: argparse.Namespace) -> int:
    if args.lanes < 1 or args.jobs < 1:
        print("woody dataset: --lanes and --jobs must be >= 1", file=sys.stderr)
        return 2
    try:
        calibration_path = str(resolve_calibration(None).absolute())
        calibration = resolved_calibration(calibration_path)
        meshes = load_meshes(args.meshes, "woody dataset")
    except ValueError as exc:
        print(f"woody dataset: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out)
    settings = {name: getattr(args, name) for name in SETTINGS}
    refused = _prepare(out, settings)
    if refused:
        print(f"woody dataset: {refused}", file=sys.stderr)
        return 2
    runs = sweep.plan(list(meshes), args.k, args.speeds, args.lanes, calibration.total_mass_kg, side=False,
                      top_camera=args.top_camera, sensor=args.sensor, conditions=tuple(args.conditions),
                      calibration=calibration_path)
    done = {path.parent.name for path in dataset.finished_runs(out)}
    todo = [r for r in runs if dataset.run_name(r) not in done]
    print(f"woody dataset: {len(meshes)} meshes x {len(args.k)} k x {len(args.speeds)} speeds x "
          f"{len(args.conditions)} conditions = {len(runs)} runs of {args.lanes} lanes ({len(runs) - len(todo)} "
          f"already in {out}, {len(todo)} to go)", file=sys.stderr)
    if not _render(args, todo, meshes):
        return 2
    names = {dataset.run_name(spec) for spec in runs}
    records = [r for name, r in dataset.read_records(out).items() if name in names]
    missing = len(runs) - len(records)
    _write_index(out, records, meshes, settings)
    print(f"woody dataset: wrote {out / 'README.md'}", file=sys.stderr)
    if missing:
        print(f"woody dataset: {missing} runs not rendered (rerun to retry)", file=sys.stderr)
    return 1 if missing else 0


def _prepare(out: Path, settings: dict) -> str | None:
    """Make the folder and record its settings; why not, in one line (a file in the way, other settings)."""
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        return f"--out {out}: cannot make the folder ({exc.strerror})"
    path = out / "dataset.json"
    if path.exists():
        before = json.loads(path.read_text())
        changed = [name for name in SETTINGS if before.get(name) != settings[name]]
        if changed:
            flags = ", ".join("--" + c.replace("_", "-") for c in changed)
            return f"{out} holds a data set made with other settings ({flags}); use another --out"
    path.write_text(json.dumps(settings, indent=2, sort_keys=True) + "\n")
    return None


def _render(args: argparse.Namespace, todo: list, meshes: dict) -> bool:
    """Render the runs on the cluster and print the throughput beside the same run's reference workload; False
    (after one line) when the cluster cannot be reached."""
    if not todo:
        return True
    options = dataset.RunOptions(out=str(Path(args.out).absolute()), side=args.side)
    frames = Counter()

    def count(records: list[dict]) -> None:
        frames["top"] += sum(len(r["frames"]) for r in records)

    reference = reference_ms()
    start = time.perf_counter()
    try:
        with cluster.connect(args.scheduler, min(args.jobs, len(todo)), "woody dataset") as client:
            stats = cluster.run_tasks(client, functools.partial(dataset.render_run, options=options), todo, meshes,
                                      count, "dataset", unit="runs")
    except cluster.ClusterUnavailable as exc:
        print(f"woody dataset: {exc}", file=sys.stderr)
        return False
    wall = time.perf_counter() - start
    per_min = frames["top"] / wall * 60.0 if wall > 0 else 0.0
    print(f"woody dataset: {frames['top']} top frames of {stats.evaluations} runs in {wall:.1f} s on "
          f"{stats.workers} workers = {per_min:.0f} frames/min; reference workload {reference:.2f} ms this run: "
          f"per_min_ref {per_min * reference / 1e3:.2f}", file=sys.stderr)
    for line in stats.failed:
        print(f"woody dataset: not rendered (rerun to retry): {line}", file=sys.stderr)
    return True


def _write_index(out: Path, records: list[dict], meshes: dict, settings: dict) -> None:
    """The COCO files per split, fillets.csv, splits.json and the datasheet, from the finished runs."""
    splits = dataset.split_meshes(list(meshes), settings["seed"])
    (out / "splits.json").write_text(json.dumps(
        {"seed": settings["seed"], "by": "mesh",
         "splits": {s: sorted(m for m, sp in splits.items() if sp == s) for s in dataset.SPLITS}},
        indent=2, sort_keys=True) + "\n")
    (out / "annotations").mkdir(exist_ok=True)
    cameras = ("top", "side") if settings["side"] else ("top",)
    for camera in cameras:
        for split, coco in dataset.coco_files(records, splits, camera).items():
            (out / "annotations" / f"{camera}_{split}.json").write_text(json.dumps(coco, sort_keys=True))
    rows = dataset.fillet_rows(records, splits)
    (out / "fillets.csv").write_text(dataset.fillets_csv(rows))
    (out / "README.md").write_text(_datasheet(records, rows, splits, meshes, settings))


def _datasheet(records: list[dict], rows: list[dict], splits: dict, meshes: dict, settings: dict) -> str:
    """README.md of the data set: what it is, how it was made, its counts per class and split, the licences."""
    command = ["woody dataset", "--out", "DIR", "--meshes", settings["meshes"],
               "--k", ",".join(f"{k:g}" for k in settings["k"]),
               "--speeds", ",".join(f"{s:g}" for s in settings["speeds"]),
               "--conditions", ",".join(settings["conditions"]), "--lanes", str(settings["lanes"]),
               "--seed", str(settings["seed"]), "--sensor", settings["sensor"], "--top-camera", settings["top_camera"]]
    command += ["--side"] if settings["side"] else []
    lines = [
        "# woody synthetic fillet data set", "",
        "Top-down RGB-D frames of a simulated multi-lane poultry fillet line (woody, a ROS 2 digital twin of a "
        "woody-breast grading line), with the truth per pixel: an instance mask per fillet from the renderer "
        "itself, and per fillet its true hinge stiffness k, its grade, mesh, lane, placement and line speed.", "",
        "## How it was made", "",
        "    " + " ".join(command), "",
        "Each run is one mesh at one stiffness, line speed and condition (how fillets lie), simulated in pybullet "
        "as a chain of rigid slices with torsional hinges and rendered by woody's rasteriser. The fillets of a run's "
        "lanes are one simulated chain posed into every lane, each seen in its lane's own perspective. Frames run "
        "from the fillets' spawn to the close of the last lane's evaluation window (the moment woody's grader "
        f"decides), at the top camera's rate. Camera error model: {settings['sensor']}.", "",
        "## Files", "",
        "| path | what |", "|---|---|",
        "| `annotations/top_<split>.json` | COCO instance segmentation: compressed RLE masks, categories "
        "normal / moderate / severe (the grade of the true k), the truth under `attributes` |",
        "| `runs/<run>/top/color/NNNN.png` | colour (rgb) |",
        "| `runs/<run>/top/depth/NNNN.png` | depth along the optical axis, 16-bit, **millimetres**, 0 = no return |",
        "| `runs/<run>/camera_info/top.yaml` | the camera (ROS camera_calibration YAML: K, D, R, P) |",
        "| `sequences/<run>/lane<L>/` | one fillet from approach to the end of its evaluation window: colour, "
        "depth and mask crops of one size, and `sequence.json` (labels; per frame its stamp, crop origin and "
        "whether it is in the window) |",
        "| `fillets.csv` | one row per fillet: truth, placement, split, frame counts, and woody's own line_phi |",
        "| `splits.json` | mesh -> split |",
    ]
    if settings["side"]:
        lines.insert(lines.index("| `splits.json` | mesh -> split |"),
                     "| `annotations/side_<split>.json`, `runs/<run>/side/color/` | the side camera (watched lane) |")
    lines += ["", f"Attributes per annotation: k, truth (woody when k >= {dataset.WOODY_K:g}, as woody's "
              "verdicts.csv), true_grade, mesh, lane, speed_fpm, speed_mps, condition, yaw_deg, leading_end, "
              "lateral_offset_m, scale, centre_x_m and front_x_m (the chain's mean and foremost slice centre "
              "along the flow, relative to the roller edge; + downstream), and woody's own verdict_status, "
              "line_phi and phi.", "",
              "## Splits", "",
              f"By mesh, drawn with seed {settings['seed']}: a model trained on `train` is evaluated on meshes it "
              "never saw.", "",
              *_split_table(records, rows, splits)]
    lines += ["", "## Meshes and licences", "", "| mesh | split | source and licence |", "|---|---|---|"]
    lines += [f"| {name} | {splits[name]} | {dataset.mesh_licence(mesh)} |" for name, mesh in sorted(meshes.items())]
    lines += ["", "The renderings of the paper's meshes are derived from the Synthetic-Chicken-Fillets data set "
              "(Apache-2.0); redistribute them with its NOTICE. The rest of the data set is Apache-2.0, as woody.", ""]
    return "\n".join(lines)


def _split_table(records: list[dict], rows: list[dict], splits: dict) -> list[str]:
    """Meshes, frames, fillets and annotations per split and class, as a markdown table."""
    frames = Counter(splits[r["mesh"]] for r in records for _ in r["frames"])
    annotations = Counter((splits[r["mesh"]], grade) for r in records for fr in r["frames"]
                          for grade in _grades(r, fr))
    fillets = Counter((row["split"], row["true_grade"]) for row in rows)
    lines = ["| split | meshes | frames | fillets " + "".join(f"| {g} " for g in GRADES)
             + "| annotations " + "".join(f"| {g} " for g in GRADES) + "|",
             "|---" * (4 + 2 * len(GRADES) + 1) + "|"]
    for split in dataset.SPLITS:
        n_meshes = sum(1 for s in splits.values() if s == split)
        lines.append(f"| {split} | {n_meshes} | {frames[split]} | {sum(fillets[(split, g)] for g in GRADES)} "
                     + "".join(f"| {fillets[(split, g)]} " for g in GRADES)
                     + f"| {sum(annotations[(split, g)] for g in GRADES)} "
                     + "".join(f"| {annotations[(split, g)]} " for g in GRADES) + "|")
    return lines


def _grades(record: dict, frame: dict) -> list[str]:
    truth = {f["lane"]: f["true_grade"] for f in record["fillets"]}
    return [truth[i["lane"]] for i in frame["fillets"]]
