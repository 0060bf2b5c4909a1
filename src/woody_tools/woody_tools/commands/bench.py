"""`woody bench sim|vision|graph|sweep|physics`: the speed figures of docs/performance.md, and what each physics
setting costs and changes (docs/physics.md).

The benchmarks themselves are :mod:`woody_tools.benchmarks`; each figure is also
printed divided by a fixed reference workload (:func:`woody_tools.benchmarks.suite.reference_ms`).
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict
from pathlib import Path

from woody_common.line import LANES, MAX_LANES, REFERENCE_SPEED_FPM, SPEED_RANGE_FPM
from woody_tools import arguments
from woody_tools.benchmarks.suite import bench_graph, bench_sim, bench_sweep, bench_vision, reference_ms, with_reference

PHYSICS_FILLETS = 6
"""Fillets on the line `bench physics` times each setting on (one per lane of a 6-lane line)."""
LANE_COUNT = arguments.number(lambda n: n == int(n) and 1 <= n <= MAX_LANES, f"must be a whole number 1..{MAX_LANES}")
LINE_SPEED = arguments.number(lambda s: SPEED_RANGE_FPM[0] <= s <= SPEED_RANGE_FPM[1],
                              f"must be within {SPEED_RANGE_FPM[0]:g}..{SPEED_RANGE_FPM[1]:g} FPM")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("target", choices=["sim", "vision", "graph", "sweep", "physics"],
                        help="what to benchmark (physics: each physics setting's cost and how far it moves the scores)")
    parser.add_argument("--json", dest="json_path", default=None, help="also write the figures to this JSON file")
    parser.add_argument("--seconds", type=float, default=10.0, help="sim seconds of each timed run (default 10)")
    parser.add_argument("--frames", type=int, default=300, help="frames per vision timing run (default 300)")
    parser.add_argument("--lanes", type=LANE_COUNT, default=LANES,
                        help=f"lanes of the line `sim` and `graph` run (default {LANES})")
    parser.add_argument("--meshes", default="builtin", help="physics: the meshes its runs use (default builtin)")
    parser.add_argument("--k", type=arguments.STIFFNESSES, default=[0.0, 100.0],
                        help="physics: hinge stiffnesses (default 0,100)")
    parser.add_argument("--speeds", type=arguments.LINE_SPEEDS, default=[100.0, 130.0],
                        help="physics: line speeds in FPM (default 100,130)")
    parser.add_argument("--live", action="store_true",
                        help="graph: run the line a second time with --live and a Foxglove client watching")
    parser.add_argument("--speed-fpm", type=LINE_SPEED, default=REFERENCE_SPEED_FPM,
                        help=f"line speed of the line `sim` and `graph` run, in FPM (default {REFERENCE_SPEED_FPM:g})")
    parser.add_argument("--line", default=None, metavar="PRESET",
                        help="graph: the line's conditions preset (woody run --line; default tidy)")
    parser.add_argument("--lane-pitch", type=float, default=None, metavar="M",
                        help="graph: distance between lane centres (woody run --lane-pitch)")
    parser.add_argument("--spacing", type=float, default=None, metavar="M",
                        help="graph: belt distance between consecutive fillets of a lane (woody run --spacing); "
                             "with --lane-pitch 0.12 and --spacing 0.26 a crowded line")
    arguments.add_physics_workers(parser, "graph: ")


def run(args: argparse.Namespace) -> int:
    reference = reference_ms()
    line = {"lanes": int(args.lanes), "speed_fpm": args.speed_fpm}
    benches = {"sim": lambda: bench_sim(args.seconds, **line),
               "vision": lambda: bench_vision(args.frames, args.seconds),
               "graph": lambda: bench_graph(**line, live=args.live, run_options=_graph_options(args)),
               "sweep": bench_sweep}
    if args.target == "physics":
        return _physics_settings(args, reference)
    figures = benches[args.target]()
    figures = {"reference_ms": reference, **with_reference(figures, 0.5 * (reference + reference_ms()))}
    width = max(len(k) for k in figures)
    for key, value in figures.items():
        # 4 significant digits: a rate per reference workload is ~0.002 and would round away with fixed decimals
        print(f"{key:<{width}}  {value:.4g}" if isinstance(value, float) else f"{key:<{width}}  {value}")
    if args.json_path:
        Path(args.json_path).write_text(json.dumps(figures, indent=2) + "\n")
        print(f"wrote {args.json_path}")
    return 0


def _graph_options(args: argparse.Namespace) -> list[str]:
    """The `woody run` options of `graph`'s line beyond lanes and speed: those given on the command line."""
    given = (("--line", args.line), ("--lane-pitch", args.lane_pitch), ("--spacing", args.spacing),
             ("--physics-workers", args.physics_workers))
    return [text for option, value in given if value is not None for text in (option, f"{value}")]


def _physics_settings(args: argparse.Namespace, reference: float) -> int:
    """The settings table: each setting timed beside the paper's chain and the reference workload, and its scores."""
    from woody_experiments.mesh_sets import load_meshes
    from woody_experiments.physics_settings import SETTINGS, evaluate_settings, markdown_table
    from woody_tools.benchmarks.physics import benchmark_physics

    meshes = list(load_meshes(args.meshes, "woody bench").values())
    runs = len(meshes) * len(args.k) * len(args.speeds)
    print(f"woody bench physics: {len(SETTINGS)} settings x {runs} runs ({len(meshes)} meshes, k {args.k}, "
          f"{args.speeds} FPM); each timed over {args.seconds:g} sim-s of a {PHYSICS_FILLETS}-fillet line", flush=True)

    def cost(config) -> float:  # the better of two runs: which fillets cross the roller together varies
        return min(1.0 / benchmark_physics(PHYSICS_FILLETS, args.seconds, config)["sim_s_per_wall_s"]
                   for _ in range(2))

    figures = evaluate_settings(meshes, args.k, args.speeds, cost, progress=lambda name: print(f"  {name}", flush=True))
    table = markdown_table(figures)
    reference = 0.5 * (reference + reference_ms())  # timed before and after, like every other bench
    print(f"reference workload {reference:.3f} ms (same run)\n\n{table}")
    if args.json_path:
        Path(args.json_path).write_text(json.dumps({"reference_ms": reference, "table": table,
                                                    "settings": [asdict(f) for f in figures]}, indent=2) + "\n")
        print(f"wrote {args.json_path}")
    return 0
