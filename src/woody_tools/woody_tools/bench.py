"""`woody bench sim` and `woody bench vision`: the speed figures the README records.

Each benchmark calls the same modules the nodes use; the end-to-end figures
(line_sim's real-time factor, verdict latency) start the real entry points as
separate processes on a private ROS domain and measure them from outside.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from woody_tools.graph import NodeProcess, lease_domain


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("target", choices=["sim", "vision"], help="what to benchmark")
    parser.add_argument("--json", dest="json_path", default=None, help="also write the figures to this JSON file")
    parser.add_argument("--seconds", type=float, default=10.0, help="sim seconds of each timed run (default 10)")
    parser.add_argument("--frames", type=int, default=300, help="frames per vision timing run (default 300)")


def run(args: argparse.Namespace) -> int:
    figures = bench_sim(args.seconds) if args.target == "sim" else bench_vision(args.frames, args.seconds)
    width = max(len(k) for k in figures)
    for key, value in figures.items():
        print(f"{key:<{width}}  {value:.3f}" if isinstance(value, float) else f"{key:<{width}}  {value}")
    if args.json_path:
        Path(args.json_path).write_text(json.dumps(figures, indent=2) + "\n")
        print(f"wrote {args.json_path}")
    return 0


def bench_sim(seconds: float) -> dict:
    from woody_sim.line_world import benchmark_physics
    from woody_sim.rendering import benchmark_rendering

    one = benchmark_physics(1, seconds)
    three = benchmark_physics(3, seconds)
    render = benchmark_rendering(n_fillets=3, frames=120)
    rtf = line_sim_rtf(seconds)
    return {
        "physics_step_ms_1": one["ms_per_step"],
        "physics_step_ms_3": three["ms_per_step"],
        "physics_dt_ms": 1000.0 * three["sim_seconds"] / three["steps"],
        "physics_rtf_3": three["sim_s_per_wall_s"],
        "render_top_ms": render["top_ms_p50"],
        "render_top_ms_p95": render["top_ms_p95"],
        "render_side_ms": render["side_ms_p50"],
        "render_side_ms_p95": render["side_ms_p95"],
        "rtf": rtf,
    }


def line_sim_rtf(seconds: float, lanes: int = 3, speed_fpm: float = 100.0) -> float:
    """Sim seconds per wall second of the real line_sim process (3 lanes, top 30 Hz, side 60 Hz)."""
    import tempfile

    import rclpy
    from rosgraph_msgs.msg import Clock

    warmup = 2.0
    with lease_domain() as lease, tempfile.TemporaryDirectory() as logs:
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=lease.domain_id)
        node = rclpy.create_node("bench_clock", context=context)
        samples: list[tuple[float, float]] = []
        node.create_subscription(Clock, "/clock", lambda m: samples.append(
            (time.monotonic(), m.clock.sec + m.clock.nanosec * 1e-9)), 100)
        sim = NodeProcess("line_sim", {"lanes": lanes, "line_speed_fpm": speed_fpm, "top_rate_hz": 30.0,
                                       "side_rate_hz": 60.0, "duration_s": warmup + seconds},
                          domain_id=lease.domain_id, log_dir=Path(logs))
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        try:
            while sim.alive():
                executor.spin_once(timeout_sec=0.1)
        finally:
            sim.stop()
            node.destroy_node()
            rclpy.try_shutdown(context=context)
        steady = [(w, s) for w, s in samples if s >= warmup]
        if len(steady) < 2:
            raise RuntimeError(f"line_sim published too little /clock to measure; see its log:\n{sim.log_tail()}")
        (w0, s0), (w1, s1) = steady[0], steady[-1]
        return (s1 - s0) / (w1 - w0)


def bench_vision(frames: int, seconds: float) -> dict:
    from woody_vision.bench import benchmark_vision

    from woody_tools.vision_latency import measure_verdict_latency

    figures = dict(benchmark_vision(frames=frames))
    latency = measure_verdict_latency(seconds)  # closing frame published -> verdict received, across processes
    figures["verdict_latency_ms_p50"] = latency["p50_ms"]
    figures["verdict_latency_ms_p95"] = latency["p95_ms"]
    figures["verdict_latency_count"] = latency["count"]
    return figures
