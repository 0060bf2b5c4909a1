"""`woody bench sim`, `woody bench vision` and `woody bench graph`: the speed figures of docs/performance.md.

The benchmarks themselves are :mod:`woody_tools.benchmarks`; each figure is also
printed divided by a fixed reference workload (:func:`woody_tools.benchmarks.suite.reference_ms`).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from woody_tools.benchmarks.suite import bench_graph, bench_sim, bench_vision, reference_ms, with_reference


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("target", choices=["sim", "vision", "graph"], help="what to benchmark")
    parser.add_argument("--json", dest="json_path", default=None, help="also write the figures to this JSON file")
    parser.add_argument("--seconds", type=float, default=10.0, help="sim seconds of each timed run (default 10)")
    parser.add_argument("--frames", type=int, default=300, help="frames per vision timing run (default 300)")


def run(args: argparse.Namespace) -> int:
    reference = reference_ms()
    benches = {"sim": lambda: bench_sim(args.seconds), "vision": lambda: bench_vision(args.frames, args.seconds),
               "graph": bench_graph}
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
