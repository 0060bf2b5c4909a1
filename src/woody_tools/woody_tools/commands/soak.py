"""`woody soak`: prove the chain stable, by N fillet passages over the roller across every condition.

The conditions and the blow-up test are :mod:`woody_sim.soak`'s, a worker's
share and the merge :mod:`woody_experiments.soak`'s; this command splits the
passages over worker processes (each with its own seed, so the workers cover
different parts of the condition grid), shows progress and prints passages,
blow-ups, the worst segment speed and the wall time.
Exit status 1 when any passage blew up.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import sys
import time
from pathlib import Path

from woody_common.calibration import resolved_calibration
from woody_common.line import MAX_LANES, REFERENCE_SPEED_FPM, fpm_to_mps, physics_worker_limit
from woody_experiments import soak
from woody_experiments.mesh_sets import load_meshes
from woody_sim.line_world import calibrated_config
from woody_sim.soak import SHIFT_SPACING_M, ShiftResult, growth_mb_per_1000, shift

MAX_SHIFT_FILLETS = 1_000_000


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--passages", type=int, default=5000,
                        help="fillet passages to run at least (whole batches of several fillets each, so a worker may "
                             "run a few more; default 5000)")
    parser.add_argument("--meshes", default=soak.DEFAULT_MESHES, help=f"mesh set (default {soak.DEFAULT_MESHES})")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="worker processes (default: cores)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the condition order (default 0)")
    parser.add_argument("--json", dest="json_path", default=None, help="also write the figures to this JSON file")
    parser.add_argument("--shift", type=int, default=0, metavar="FILLETS",
                        help="instead: a messy line of FILLETS placed fillets (each turned, sized and offset its own "
                             "way) through one physics world, as line_sim runs for hours, printing the process's "
                             "resident memory as they leave and its growth per 1,000 fillets")
    parser.add_argument("--lanes", type=int, default=3, help="with --shift: lanes, 1-6 (default 3)")
    parser.add_argument("--physics-workers", type=int, default=0, metavar="N",
                        help="with --shift: run the physics in N worker processes, as line_sim's physics_workers "
                             "(default 0: in this process)")
    parser.add_argument("--recycle-after", type=int, default=0, metavar="FILLETS",
                        help="with --shift and --physics-workers: replace each worker after it has taken FILLETS "
                             "fillets, as line_sim's physics_recycle_fillets (default 0: never)")


def run(args: argparse.Namespace) -> int:
    if args.shift:
        return run_shift(args)
    from tqdm import tqdm

    meshes = _checked_meshes(args, "--passages and --jobs must be >= 1", args.passages >= 1 and args.jobs >= 1)
    if meshes is None:
        return 2
    jobs = min(args.jobs, args.passages)
    share = [args.passages // jobs + (i < args.passages % jobs) for i in range(jobs)]
    t0 = time.perf_counter()
    with mp.get_context("spawn").Manager() as manager, mp.get_context("spawn").Pool(jobs) as pool:
        queue = manager.Queue()
        pending = pool.map_async(soak.work, [(args.meshes, n, args.seed + i, queue) for i, n in enumerate(share)])
        with tqdm(total=args.passages, unit="passage", file=sys.stderr, dynamic_ncols=True) as bar:
            while not pending.ready() or not queue.empty():
                while not queue.empty():
                    bar.update(queue.get())
                pending.wait(0.2)
        summary = soak.merge(pending.get())
    summary.update(wall_s=time.perf_counter() - t0, jobs=jobs, meshes=args.meshes, n_meshes=len(meshes))
    print(f"passages {summary['passages']}, blow-ups {summary['blowups']}, worst segment speed "
          f"{summary['worst_segment_speed_mps']:.2f} m/s, {summary['sim_s']:.0f} sim-s in {summary['wall_s']:.0f} s "
          f"on {jobs} workers ({len(meshes)} meshes)")
    for condition in summary["failed_conditions"]:
        print(f"  blew up: {condition}")
    if args.json_path:
        Path(args.json_path).write_text(json.dumps(summary, indent=2) + "\n")
    return 1 if summary["blowups"] else 0


def run_shift(args: argparse.Namespace) -> int:
    """The shift soak (``--shift``): a long messy line through one LineWorld in this process or recycled physics
    workers; exit 1 on a blow-up."""
    from tqdm import tqdm

    cores = physics_worker_limit()
    rule = (f"--shift must be 1..{MAX_SHIFT_FILLETS}, --lanes 1..{MAX_LANES}, --physics-workers 0..{cores} "
            "(the cores) and --recycle-after >= 0 (above 0 with --physics-workers >= 1)")
    ok = (1 <= args.shift <= MAX_SHIFT_FILLETS and 1 <= args.lanes <= MAX_LANES and 0 <= args.physics_workers <= cores
          and (args.recycle_after == 0 or (args.recycle_after > 0 and args.physics_workers >= 1)))
    meshes = _checked_meshes(args, rule, ok)
    if meshes is None:
        return 2
    calibration = resolved_calibration()
    with tqdm(total=args.shift, unit="fillet", file=sys.stderr, dynamic_ncols=True) as bar:
        result = shift(list(meshes.values()), args.shift, calibration.total_mass_kg, lanes=args.lanes,
                       seed=args.seed, config=calibrated_config(calibration), progress=bar.update,
                       workers=args.physics_workers, recycle_after=args.recycle_after,
                       on_sample=lambda sampled: bar.write(_sample_line(sampled)))
    growth, worker_growth = growth_mb_per_1000(result.rss_mb), growth_mb_per_1000(result.worker_rss_mb)
    _print_memory(result, args.lanes, growth, worker_growth)
    if args.json_path:
        figures = vars(result) | {"growth_mb_per_1000": growth, "worker_growth_mb_per_1000": worker_growth}
        Path(args.json_path).write_text(json.dumps(figures, indent=2) + "\n")
    return 1 if result.blowups else 0


def _sample_line(result: ShiftResult) -> str:
    """The latest memory sample, as the soak goes (a shift runs for hours)."""
    gone, rss = result.rss_mb[-1]
    workers = dict(result.worker_rss_mb)
    there = f", largest physics worker {workers[gone]:7.1f} MB" if gone in workers else ""
    return f"  {gone:6d} fillets gone: {rss:7.1f} MB{there}"


def _print_memory(result: ShiftResult, lanes: int, growth: float, worker_growth: float) -> None:
    """The growth per 1,000 fillets and per hour of this line (the samples went out as they were taken)."""
    hour = lanes * fpm_to_mps(REFERENCE_SPEED_FPM) / SHIFT_SPACING_M * 3600.0
    print(f"shift: {result.fillets} messy fillets, {result.blowups} blow-ups, {result.sim_s:.0f} sim-s in "
          f"{result.wall_s:.0f} s; resident memory {growth:+.1f} MB per 1,000 fillets over the second half "
          f"({growth * hour / 1000.0:+.0f} MB per hour of a {lanes}-lane line at 100 FPM, "
          f"{SHIFT_SPACING_M:g} m apart: {hour:.0f} fillets)")
    if result.worker_rss_mb:
        print(f"physics workers: {result.workers_started} started; the largest {worker_growth:+.1f} MB per 1,000 "
              "fillets over the second half")


def _checked_meshes(args: argparse.Namespace, rule: str, ok: bool) -> dict | None:
    """The mesh set when the options keep ``rule`` (``ok``) and it loads; else None after one line saying why."""
    if not ok:
        print(f"woody soak: {rule}", file=sys.stderr)
        return None
    try:
        return load_meshes(args.meshes, "woody soak")
    except ValueError as exc:
        print(f"woody soak: {exc}", file=sys.stderr)
        return None
