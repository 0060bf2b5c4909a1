"""`woody bench sim|vision|graph|sweep`: the speed figures of docs/performance.md.

Each benchmark calls the same modules the nodes use; the end-to-end figures
(line_sim's real-time factor, verdict latency, `woody run`, a sweep) start the
real entry points as separate processes and measure them from outside.

Machines differ about 2x and a shared one varies from minute to minute, so
every run also times a fixed reference workload (numpy and plain Python,
:func:`reference_ms`) and prints each figure divided by it (``*_ref``: a time
in reference workloads, a rate per reference workload); the renderer is also
compared with pybullet's TinyRenderer on the same scene.
"""

from __future__ import annotations

import csv
import math
import re
import statistics
import subprocess
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from woody_common.line import LANES, REFERENCE_SPEED_FPM
from woody_common.stamps import stamp_to_seconds
from woody_sim.loop_phases import parse_summary
from woody_tools.processes import NodeProcess, entry_point, lease_domain


def reference_ms(repeats: int = 9) -> float:
    """Median wall ms of a fixed workload (a 200x200 matmul, a sort of a frame-sized array, a Python loop)."""
    rng = np.random.default_rng(0)
    matrix = rng.random((200, 200))
    frame = rng.random((376, 672)).astype(np.float32)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        matrix @ matrix
        np.sort(frame, axis=None)
        total = 0.0
        for i in range(20000):
            total += i * 0.5
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


RATES = ("rtf", "per_min")
"""Keys containing these are rates (more is faster); the other keys with _ms are times ..."""
NOT_TIMED = {"physics_dt_ms"}
"""... except these (settings, not measurements)."""


def with_reference(figures: dict, reference: float) -> dict:
    """Each figure followed by its value in reference workloads (times) or per reference workload (rates)."""
    out = {}
    for key, value in figures.items():
        out[key] = value
        if isinstance(value, float) and any(r in key for r in RATES):
            out[f"{key}_ref"] = value * reference / 1e3
        elif isinstance(value, float) and "_ms" in key and key not in NOT_TIMED:
            out[f"{key}_ref"] = value / reference
    return out


def bench_sim(seconds: float, lanes: int = LANES, speed_fpm: float = REFERENCE_SPEED_FPM) -> dict:
    """Physics and rendering alone, then the real line_sim at ``lanes`` and ``speed_fpm``: its real-time factor,
    where its loop spends the wall time, and the same line without physics workers and with a 200 Hz side
    camera."""
    from woody_tools.benchmarks.physics import benchmark_physics
    from woody_tools.benchmarks.rendering import benchmark_rendering

    physics = {n: benchmark_physics(n, seconds) for n in (1, 3, 6)}
    render = benchmark_rendering(n_fillets=3, frames=120)
    figures = {f"physics_step_ms_{n}": p["ms_per_step"] for n, p in physics.items()}
    figures["physics_dt_ms"] = 1000.0 * physics[3]["sim_seconds"] / physics[3]["steps"]
    figures.update({f"physics_rtf_{n}": physics[n]["sim_s_per_wall_s"] for n in (3, 6)})
    for view in ("top", "side"):
        figures[f"render_{view}_ms"] = render[f"{view}_ms_p50"]
        figures[f"render_{view}_ms_p95"] = render[f"{view}_ms_p95"]
        figures[f"tinyrenderer_{view}_ms"] = render[f"tiny_{view}_ms_p50"]
        figures[f"render_{view}_speedup_vs_tinyrenderer"] = render[f"{view}_speedup_vs_tiny"]
    line = {"lanes": lanes, "speed_fpm": speed_fpm}
    figures.update(lanes=lanes, speed_fpm=speed_fpm)
    figures["rtf"], phases = line_sim_rtf(seconds, **line)
    figures.update({f"phase_{name}_pct": share for name, share in phases.items()})
    figures["rtf_without_physics_worker"] = line_sim_rtf(seconds, physics_workers=0, **line)[0]
    figures["rtf_side_200hz"] = line_sim_rtf(seconds, side_rate_hz=200.0, **line)[0]
    return figures


def bench_graph(lanes: int = LANES, speed_fpm: float = REFERENCE_SPEED_FPM, spawn_s: float = 10.0,
                live: bool = False, run_options: Sequence[str] = ()) -> dict:
    """`woody run` (the whole graph with the recorder) at ``lanes`` and ``speed_fpm``, spawning for ``spawn_s`` sim
    seconds so the line runs full, as a subprocess: its speed, its node start-up, whether every fillet got its
    verdict and whether the recorder lost anything. ``run_options``: more `woody run` options (the line's preset,
    lane pitch and spacing, its physics workers). With ``live``, the same line once more with ``--live`` and a
    Foxglove client watching the colour image, the annotations and the verdicts: the view's cost to the line."""
    line = ["--lanes", str(lanes), "--speed-fpm", f"{speed_fpm:g}", "--duration", f"{spawn_s:g}", *run_options]
    figures = {"lanes": lanes, "speed_fpm": speed_fpm, "line": " ".join(run_options) or "tidy",
               **_graph_run(line, "woody_run")}
    if live:
        figures.update(_graph_run(line, "woody_run_live"))
        figures["woody_run_live_pace_ratio"] = figures["woody_run_live_line_rtf"] / figures["woody_run_line_rtf"]
    return figures


LIVE_WATCHED = {"/top_camera/color/image_raw", "/grading/annotations", "/grading/verdicts"}


def _graph_run(line: list[str], name: str) -> dict:
    """One `woody run` of ``line`` (with ``--live`` and a watching client when ``name`` ends in ``_live``)."""
    from woody_bag.foxglove_client import Watcher

    live = name.endswith("_live")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run"
        run = subprocess.Popen([entry_point("woody"), "run", *line, "--out", str(out), *(["--live", "0"] * live)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        watcher = Watcher(f"ws://127.0.0.1:{_view_port(out, run)}", LIVE_WATCHED) if live else None
        stdout, stderr = run.communicate()
        if run.returncode:
            raise RuntimeError(f"woody run failed:\n{stderr[-2000:]}")
        with open(out / "verdicts.csv", newline="") as rows:
            fillets = list(csv.DictReader(rows))
    rtf = re.search(r"wall: rtf ([0-9.]+)x", stdout)
    started = re.search(r"the line itself, after ([0-9.]+) s of node start-up: rtf ([0-9.]+)x", stdout)
    if rtf is None or started is None:
        raise RuntimeError(f"woody run did not report its speed:\n{stdout[-2000:]}")
    lost = re.search(r"recorder: ([0-9]+) messages lost", stdout + stderr)
    figures = {f"{name}_fillets": len(fillets), f"{name}_verdicts": sum(1 for row in fillets if row["verdict"]),
               f"{name}_rtf": float(rtf.group(1)), f"{name}_line_rtf": float(started.group(2)),
               f"{name}_startup_s": float(started.group(1)), f"{name}_recorder_lost": int(lost.group(1)) if lost else 0}
    if watcher is not None:
        watcher.join(30.0)
        figures[f"{name}_client_frames"] = len(watcher.received["/top_camera/color/image_raw"])
    return figures


def _view_port(out: Path, run: subprocess.Popen, timeout_s: float = 120.0) -> int:
    """The port the line's foxglove_view serves on, from its log."""
    from woody_bag.foxglove_client import served_port

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and run.poll() is None:
        port = served_port(out / "logs" / "foxglove_view.log")
        if port is not None:
            return port
        time.sleep(0.1)
    raise RuntimeError(f"foxglove_view named no port within {timeout_s:g} s")


def bench_sweep() -> dict:
    """`woody sweep` of the default grid (its 30 meshes, 9 stiffnesses, 2 speeds, 3 lanes, side view on), as a
    subprocess: evaluations per minute, and one warm worker's rate in the same sweep."""
    with tempfile.TemporaryDirectory() as tmp:
        sweep = subprocess.run([entry_point("woody"), "sweep", "--no-report", "--out", str(Path(tmp) / "sweep")],
                               check=True, capture_output=True, text=True)
    text = sweep.stdout + sweep.stderr
    rate = re.search(r"([0-9]+) fillet evaluations in ([0-9.]+) s = ([0-9.]+) /min", text)
    alone = re.search(r"against ([0-9.]+) /min with one warm worker alone", text)
    if rate is None:
        raise RuntimeError(f"woody sweep did not report its speed:\n{text[-2000:]}")
    return {"sweep_evaluations": int(rate.group(1)), "sweep_wall_s": float(rate.group(2)),
            "sweep_evals_per_min": float(rate.group(3)),
            "sweep_one_worker_evals_per_min": float(alone.group(1)) if alone else math.nan}


def line_sim_rtf(seconds: float, lanes: int = LANES, speed_fpm: float = REFERENCE_SPEED_FPM,
                 side_rate_hz: float = 60.0, physics_workers: int | None = None) -> tuple[float, dict[str, float]]:
    """Sim seconds per wall second of the real line_sim process (top 30 Hz, side ``side_rate_hz``; its default
    physics workers unless ``physics_workers`` is given), and its loop's wall time by phase (percent)."""
    import rclpy
    from rosgraph_msgs.msg import Clock

    warmup = 2.0
    params = {"lanes": lanes, "line_speed_fpm": speed_fpm, "top_rate_hz": 30.0, "side_rate_hz": side_rate_hz,
              "duration_s": warmup + seconds}
    if physics_workers is not None:
        params["physics_workers"] = physics_workers
    with lease_domain() as lease, tempfile.TemporaryDirectory() as logs:
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=lease.domain_id)
        node = rclpy.create_node("bench_clock", context=context)
        samples: list[tuple[float, float]] = []
        node.create_subscription(Clock, "/clock", lambda m: samples.append(
            (time.monotonic(), stamp_to_seconds(m.clock))), 100)
        sim = NodeProcess("line_sim", params, domain_id=lease.domain_id, log_dir=Path(logs))
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        try:
            while sim.alive():
                executor.spin_once(timeout_sec=0.1)
        finally:
            sim.stop()
            node.destroy_node()
            rclpy.try_shutdown(context=context)
        phases = parse_summary(sim.log_path.read_text(errors="replace"))
        steady = [(w, s) for w, s in samples if s >= warmup]
        if len(steady) < 2:
            raise RuntimeError(f"line_sim published too little /clock to measure; see its log:\n{sim.log_tail()}")
        (w0, s0), (w1, s1) = steady[0], steady[-1]
        return (s1 - s0) / (w1 - w0), phases


def bench_vision(frames: int, seconds: float) -> dict:
    from woody_tools.benchmarks.verdict_latency import measure_verdict_latency
    from woody_tools.benchmarks.vision import benchmark_vision

    figures = dict(benchmark_vision(frames=frames))
    latency = measure_verdict_latency(seconds)  # deciding frame published -> verdict received, across processes
    figures["verdict_latency_ms_p50"] = latency["p50_ms"]
    figures["verdict_latency_ms_p95"] = latency["p95_ms"]
    figures["verdict_latency_count"] = latency["count"]
    return figures
