"""`woody run`: the whole line as separate processes on a private ROS domain.

Starts recorder, segmenter, grader, reject_gate and line_sim, watches ground
truth, verdicts and /clock from this process to show progress, stops
everything when every fillet is graded (or on Ctrl-C, or when a node dies),
and leaves the bag, verdicts.csv and report.md in the output folder.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import time
from datetime import datetime
from pathlib import Path

from woody_tools.cpu_usage import CpuAccounting
from woody_tools.graph import NodeProcess, lease_domain, wait_for
from woody_tools.report import Spawn, Verdict, build_report, join, verdict_table, write_csv


MAX_LEAD_S = 0.1
"""line_sim runs at most this far (sim s, 3 top frames) ahead of the segmenter, whose queue holds 5 frames."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--lanes", type=int, default=3, help="lanes across the belt, 1-6 (default 3)")
    parser.add_argument("--speed-fpm", type=float, default=100.0, help="line speed in feet per minute (default 100)")
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--fillets", type=int, default=None, help="total fillets to spawn (default 12)")
    group.add_argument("--duration", type=float, default=None, help="sim seconds of spawning instead of a count")
    parser.add_argument("--k", type=float, nargs="+", default=[0.0, 100.0],
                        help="stiffness values to mix, N*m/rad (default: 0 normal, 100 woody)")
    parser.add_argument("--meshes", default="builtin",
                        help="builtin, generated:N[:SEED], a folder of meshes; comma-combinable (default builtin)")
    parser.add_argument("--seed", type=int, default=7, help="seed of the fillet mix (default 7)")
    parser.add_argument("--out", default=None, help="output folder (default bags/run-<time>)")
    parser.add_argument("--realtime", action="store_true", help="pace the simulation to the wall clock")
    parser.add_argument("--threshold", type=float, default=None, help="Φ threshold of the grader (default: its own)")
    parser.add_argument("--side-rate", type=float, default=60.0, help="side camera frame rate, Hz (default 60)")
    parser.add_argument("--timeout", type=float, default=1800.0, help="wall-clock limit in seconds (default 1800)")


def _validate(args: argparse.Namespace) -> None:
    if not 1 <= args.lanes <= 6:
        raise SystemExit(f"woody run: --lanes must be 1..6, got {args.lanes}")
    if not 0 < args.speed_fpm <= 400:
        raise SystemExit(f"woody run: --speed-fpm must be in (0, 400], got {args.speed_fpm}")
    if args.fillets is not None and args.fillets < 1:
        raise SystemExit(f"woody run: --fillets must be >= 1, got {args.fillets}")
    if any(k < 0 for k in args.k):
        raise SystemExit(f"woody run: --k values must be >= 0, got {args.k}")


class LineMonitor:
    """This process's view of the line: ground truth, verdicts, gate commands and sim time."""

    def __init__(self, domain_id: int) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from rosgraph_msgs.msg import Clock
        from woody_msgs.msg import FilletSpawn, FilletVerdict, GateCommand

        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node("woody_run_monitor", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        latched = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        reliable = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        self.spawns: list[Spawn] = []
        self.verdicts: list[Verdict] = []
        self.gate_commands = 0
        self.sim_time = 0.0
        self.node.create_subscription(FilletSpawn, "/line/ground_truth", self._on_spawn, latched)
        self.node.create_subscription(FilletVerdict, "/grading/verdicts", self._on_verdict, reliable)
        self.node.create_subscription(GateCommand, "/reject_gate/commands", self._on_gate, reliable)
        self.node.create_subscription(Clock, "/clock", self._on_clock, 10)

    def _on_spawn(self, msg) -> None:
        self.spawns.append(Spawn(sim_id=msg.fillet_id, lane=msg.lane, mesh=msg.mesh, k=msg.stiffness, mass=msg.mass,
                                 line_speed=msg.line_speed, stamp=_seconds(msg.header.stamp), spawn_x=msg.position.x))

    def _on_verdict(self, msg) -> None:
        self.verdicts.append(verdict_from_msg(msg))

    def _on_gate(self, msg) -> None:
        self.gate_commands += 1

    def _on_clock(self, msg) -> None:
        self.sim_time = _seconds(msg.clock)

    def spin(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=max(0.0, deadline - time.monotonic()))

    def close(self) -> None:
        import rclpy

        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def _seconds(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def verdict_from_msg(msg) -> Verdict:
    """Flatten a woody_msgs/FilletVerdict into the report's Verdict."""
    classes = {msg.CLASS_NORMAL: "normal", msg.CLASS_WOODY: "woody", msg.CLASS_UNSCORED: "unscored"}
    return Verdict(fillet_id=msg.fillet_id, lane=msg.lane, stamp=_seconds(msg.header.stamp),
                   classification=classes.get(msg.classification, "unscored"), grade=msg.grade, phi=msg.phi,
                   hu_term=msg.hu_term, solidity_term=msg.solidity_term, nmdm=msg.nmdm, mdm=msg.mdm, be=msg.be,
                   reason=msg.unscored_reason)


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    _validate(args)
    fillets = args.fillets if args.fillets is not None or args.duration is not None else 12
    out = Path(args.out) if args.out else Path("bags") / datetime.now().strftime("run-%Y%m%d-%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    logs = out / "logs"
    bag = out / "line.mcap"
    if bag.exists():
        bag.unlink()

    lease = lease_domain()
    print(f"woody run: ROS_DOMAIN_ID={lease.domain_id}, output {out}/", flush=True)
    sim_params: dict[str, object] = {
        "lanes": args.lanes, "line_speed_fpm": args.speed_fpm, "k_values": [float(k) for k in args.k],
        "meshes": args.meshes, "seed": args.seed, "fillets": fillets or 0, "spawn_duration_s": args.duration or 0.0,
        "realtime": args.realtime, "side_rate_hz": args.side_rate, "wait_for_subscribers": 2,
        "max_lead_s": MAX_LEAD_S,
    }
    vision_params: dict[str, object] = {"use_sim_time": True, "lanes": args.lanes}
    grader_params = dict(vision_params)
    if args.threshold is not None:
        grader_params["threshold"] = args.threshold

    nodes: list[NodeProcess] = []
    monitor = None
    cpu = None
    rows: list[dict] = []
    stopping = {"signal": None}

    def on_signal(signum, _frame):
        stopping["signal"] = signum

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    error = None
    try:
        start = lambda name, params: nodes.append(NodeProcess(name, params, domain_id=lease.domain_id, log_dir=logs))
        start("recorder", {"use_sim_time": True, "output": str(bag)})
        start("segmenter", vision_params)
        start("grader", grader_params)
        start("reject_gate", {"use_sim_time": True, "lanes": args.lanes, "line_speed_fpm": args.speed_fpm})
        start("line_sim", sim_params)
        monitor = LineMonitor(lease.domain_id)
        cpu = CpuAccounting({"woody run": os.getpid(), **{n.name: n.process.pid for n in nodes}})
        wall_start = time.monotonic()
        bar = tqdm(total=fillets or None, unit="fillet", desc="graded", dynamic_ncols=True, mininterval=1.0,
                   file=sys.stderr, disable=None if sys.stderr.isatty() else True)
        last_line = 0.0
        done_since = None
        while True:
            monitor.spin(0.25)
            cpu.sample()
            graded = len(monitor.verdicts)
            elapsed = time.monotonic() - wall_start
            status = (f"spawned {len(monitor.spawns)}, sim {monitor.sim_time:.1f} s, "
                      f"rtf {monitor.sim_time / max(elapsed, 1e-9):.2f}x")
            if bar.disable and time.monotonic() - last_line >= 10.0:  # not a terminal: a plain line now and then
                print(f"graded {graded}/{fillets or '?'} fillets, {status}", file=sys.stderr, flush=True)
                last_line = time.monotonic()
            bar.update(min(graded, bar.total or graded) - bar.n)
            bar.set_postfix_str(status, refresh=False)
            dead = [n for n in nodes if not n.alive()]
            if dead:
                node = dead[0]
                error = f"node '{node.name}' exited with code {node.returncode}; last lines of {node.log_path}:\n{node.log_tail()}"
                break
            if stopping["signal"] is not None:
                error = "interrupted"
                break
            if elapsed > args.timeout:
                error = f"timed out after {args.timeout:.0f} s of wall time"
                break
            if _finished(monitor, fillets, args):
                done_since = done_since or time.monotonic()
                if time.monotonic() - done_since > 1.0:
                    break
        bar.close()
    finally:
        if cpu is not None:
            cpu.sample()
            wall = time.monotonic() - wall_start
        for node in nodes:
            if node.name != "recorder":
                node.signal(signal.SIGINT)
        deadline = time.monotonic() + 10.0
        for node in nodes:  # one SIGINT each: a second one would interrupt a node's own clean shutdown
            if node.name != "recorder":
                wait_for(lambda: not node.alive(), timeout=max(0.0, deadline - time.monotonic()))
        for node in nodes:
            if node.name != "recorder":
                node.stop(timeout=10.0)
        for node in nodes:
            if node.name == "recorder":
                node.stop(timeout=30.0)
        if monitor is not None:
            rows = join(monitor.spawns, monitor.verdicts)
            monitor.close()
        lease.release()
        for sig, handler in previous.items():
            signal.signal(sig, handler)

    if monitor is None:
        print(f"woody run: {error or 'the line did not start'}", file=sys.stderr)
        return 1
    csv_path = write_csv(rows, out / "verdicts.csv")
    info = {"lanes": args.lanes, "line speed (FPM)": args.speed_fpm, "stiffness mix k": ", ".join(f"{k:g}" for k in args.k),
            "meshes": args.meshes, "seed": args.seed, "fillets spawned": len(monitor.spawns),
            "verdicts": len(monitor.verdicts), "gate commands": monitor.gate_commands,
            "sim time (s)": f"{monitor.sim_time:.1f}", "paced to wall clock": args.realtime}
    report = build_report(rows, out, title="woody line run", run_info=info)
    print(verdict_table(rows))
    print(f"\nbag: {bag}\nverdicts: {csv_path}\nreport: {report}\nnode logs: {logs}/")
    print(f"sim {monitor.sim_time:.1f} s in {wall:.1f} s wall: rtf {monitor.sim_time / max(wall, 1e-9):.2f}x")
    print(cpu.summary(wall))
    if error:
        print(f"woody run: {error}", file=sys.stderr)
        return 1
    return 0


def _finished(monitor: LineMonitor, fillets: int | None, args: argparse.Namespace) -> bool:
    """Every spawned fillet has a verdict, or has had ample sim time to get one."""
    if fillets and len(monitor.spawns) < fillets:
        return False
    if not fillets and monitor.sim_time < (args.duration or 0.0):
        return False
    if not monitor.spawns:
        return False
    if len(monitor.verdicts) >= len(monitor.spawns):
        return True
    last = max(s.expected_crossing for s in monitor.spawns)
    return monitor.sim_time > last + 4.0
