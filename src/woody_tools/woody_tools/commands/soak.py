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

from woody_experiments import soak
from woody_experiments.mesh_sets import load_meshes


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--passages", type=int, default=5000,
                        help="fillet passages to run at least (whole batches of several fillets each, so a worker may "
                             "run a few more; default 5000)")
    parser.add_argument("--meshes", default=soak.DEFAULT_MESHES, help=f"mesh set (default {soak.DEFAULT_MESHES})")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="worker processes (default: cores)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the condition order (default 0)")
    parser.add_argument("--json", dest="json_path", default=None, help="also write the figures to this JSON file")


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    if args.passages < 1 or args.jobs < 1:
        print("woody soak: --passages and --jobs must be >= 1", file=sys.stderr)
        return 2
    try:
        meshes = load_meshes(args.meshes, "woody soak")
    except ValueError as exc:
        print(f"woody soak: {exc}", file=sys.stderr)
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
