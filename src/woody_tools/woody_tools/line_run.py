"""The processes of `woody run`: the whole line as separate processes on a private ROS domain.

Starts recorder, segmenter, grader, reject_gate and line_sim, watches ground
truth, verdicts and the top camera's stamps from this process to show progress, stops
everything when every fillet is graded (or on Ctrl-C, or when a node dies),
and leaves the bag, verdicts.csv and report.md in the output folder. The
options are :mod:`woody_tools.commands.run`'s.
"""

from __future__ import annotations

import argparse
import fcntl
import json
import os
import shutil
import signal
import sys
import time
from datetime import datetime
from pathlib import Path

from woody_bag.errors import BagError
from woody_bag.recorder_node import recorder_failure
from woody_bag.summary import bag_summary, losses_text, recorded_losses, recording_text, unrecorded_topics
from woody_common import topics
from woody_common.dds_shm import remove_stale
from woody_common.diagnostics import GRADED_UP_TO
from woody_common.line import PAPER_PHYSICS_RATE_HZ, PAPER_SEGMENTS, fpm_to_mps, spacing_at_rate, watched_lane
from woody_common.stamps import stamp_to_seconds
from woody_experiments.fillet_pictures import write_fillet_pictures
from woody_experiments.messages import (
    LineRecords,
    gate_margin,
    records_from_bag,
    side_from_msg,
    spawn_from_msg,
    verdict_from_msg,
)
from woody_experiments.run_report import (
    CALIBRATED_SPEEDS,
    MATCH_TOLERANCE_S,
    OUTSIDE_GRADED,
    RECORDING,
    UNSCORED_DIVERTED,
    SideRecord,
    Spawn,
    Verdict,
    build_report,
    diversion_summary,
    other_camera_note,
    uncalibrated_speed_note,
    unscored_diverted,
    verdict_table,
    write_csv,
)
from woody_sim.camera_description import is_camera_file, load_camera
from woody_sim.line_conditions import LineConditions, crowding_note, longest_placed_length
from woody_sim.line_geometry import LineGeometry, top_camera_preset
from woody_tools.cpu_usage import CpuAccounting
from woody_tools.processes import STOP, DomainInUse, NodeProcess, lease_domain
from woody_vision.grader_core import SCORE_LINE
from woody_vision.grading import CUT_TERMS
from woody_vision.segmentation import REAL_CAMERA_FILTERS

MAX_LEAD_S = 0.15
"""line_sim runs at most this far (sim s, 4.5 top frames) ahead of the segmenter, whose queue holds 5 frames, and
of the recorder's written clock. At 0.1 s the line waited a quarter of its time on a consumer that had only just
finished the frame before: 6 lanes at 130 FPM ran 1.02-1.06x, against 1.8-1.9x at 0.15 s."""


FAILED_DIR = "failed"
"""Where a run that graded nothing leaves its bag and logs, inside --out."""
HANGUP_LOG = "woody_run.log"
"""In the run's logs/: what woody run prints once its terminal has closed (SIGHUP)."""
INTERRUPTED = "interrupted"
"""Why the watch ended early: a stop signal (STOP)."""
LOST_NOTE = "the bag misses them (verdicts.csv does not: it joins the bag with what woody run heard live)"
"""Follows the messages the recorder lost in woody run's line and report.md's note."""
OUTPUTS_UNWRITTEN = "cannot write to"
"""Begins woody run's line when --out takes no more (a full disk); the exit code is then 1."""


class RunRefused(Exception):
    """An input `woody run` cannot work with; the message is one line (printed, exit code 2)."""


class RunInterrupted(Exception):
    """A stop signal before the nodes started; the message is one line (printed, exit code 128 + the signal)."""


def _claim_out(out: Path, force: bool):
    """Create ``out`` and lock it for this run: one line when it is unwritable, in use, or holds a run already."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        lock = open(out / ".woody-run.lock", "w")
    except OSError as exc:
        raise RunRefused(f"--out {out}: cannot write there ({exc.strerror or exc})") from None
    try:
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        lock.close()
        raise RunRefused(f"--out {out} is in use by another woody run; choose another folder") from None
    bag = out / "line.mcap"
    if bag.exists() and not force:
        lock.close()
        raise RunRefused(f"--out {out} already holds a run ({bag.name}); pass --force to overwrite it "
                         "or choose another folder")
    bag.unlink(missing_ok=True)
    return lock


def _check_meshes(spec: str) -> tuple[list, list[str]]:
    """The loadable meshes of ``spec``, and one line per mesh file that line_sim would skip or convert, checked
    here so the terminal and report.md name them (line_sim only logs them)."""
    from woody_sim.meshes import checked_mesh_set

    try:
        return checked_mesh_set(spec)
    except ValueError as exc:
        raise RunRefused(f"--meshes: {exc}") from None


def _crowding_notes(meshes: list, args: argparse.Namespace) -> list[str]:
    """The note line_sim logs when fillets of a lane may have to wait for room (spacing below the longest placed
    fillet)."""
    speeds = dict.fromkeys((args.speed_fpm, args.speed_change_fpm or args.speed_fpm))
    if args.fillets_per_minute is not None:
        spacing = min(spacing_at_rate(fpm_to_mps(fpm), args.fillets_per_minute) for fpm in speeds)
    elif args.spacing is not None:
        spacing = args.spacing
    else:
        return []
    note = crowding_note(spacing, longest_placed_length(meshes, args.conditions))
    return [note] if note else []


class LineMonitor:
    """This process's view of the line: ground truth, verdicts, gate commands and sim time."""

    def __init__(self, domain_id: int, namespace: str = "") -> None:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from rclpy.signals import SignalHandlerOptions
        from sensor_msgs.msg import CameraInfo

        from woody_msgs.msg import FilletSpawn, FilletVerdict, GateCommand, SideMetrics

        self.domain_id = domain_id
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node("woody_run_monitor", context=self.context,
                                      namespace="/" + namespace.strip("/"))
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        latched = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        reliable = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        self.spawns: list[Spawn] = []
        self.verdicts: list[Verdict] = []
        self.sides: list[SideRecord] = []
        self.gate_commands: dict[tuple[int, int], float] = {}
        """(lane, fillet id) of every GateCommand: the fillets the gate acted on in time."""
        self.sim_time = 0.0
        self.first_frame: tuple[float, float] | None = None
        """(wall monotonic, sim s) of the first top camera frame: when the line itself started, after the nodes'
        start-up. Sim time is followed by the frames' 30 Hz camera_info, not /clock's 200+ Hz: each message costs
        this process a callback."""
        self.last_frame: tuple[float, float] | None = None
        self.health: dict[str, tuple[int, str]] = {}
        """Node name -> (level, message) of its latest /diagnostics status."""
        self.graded_up_to: float | None = None
        """The grader's latest graded track stamp by its /diagnostics (sim s); None before it reports one."""
        self.node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, self._on_diagnostics, 50)
        self.node.create_subscription(FilletSpawn, topics.GROUND_TRUTH, self._on_spawn, latched)
        self.node.create_subscription(FilletVerdict, topics.VERDICTS, self._on_verdict, reliable)
        self.node.create_subscription(SideMetrics, topics.SIDE_METRICS, self._on_side, reliable)
        self.node.create_subscription(GateCommand, topics.GATE_COMMANDS, self._on_gate, reliable)
        self.node.create_subscription(CameraInfo, topics.TOP_DEPTH_INFO, self._on_frame, 10)

    def _on_diagnostics(self, msg) -> None:
        for status in msg.status:
            name = status.name.rsplit("/", 1)[-1]
            self.health[name] = (status.level[0], status.message)
            if name == "grader":
                self.graded_up_to = next((float(kv.value) for kv in status.values if kv.key == GRADED_UP_TO),
                                         self.graded_up_to)

    def graded_time(self) -> float:
        """Sim time the line has been graded up to: the grader's progress where it reports one, else the
        line's."""
        return self.sim_time if self.graded_up_to is None else min(self.sim_time, self.graded_up_to)

    def holding_up(self) -> list[str]:
        """What holds the line up now, by its nodes' diagnostics: what line_sim waits for, and every node in
        error (e.g. waiting for camera_info)."""
        from diagnostic_msgs.msg import DiagnosticStatus

        error, warn = DiagnosticStatus.ERROR[0], DiagnosticStatus.WARN[0]
        return [f"{name}: {message}" for name, (level, message) in sorted(self.health.items())
                if level >= error or (name == "line_sim" and level == warn)]

    def _on_spawn(self, msg) -> None:
        self.spawns.append(spawn_from_msg(msg))

    def _on_verdict(self, msg) -> None:
        self.verdicts.append(verdict_from_msg(msg))

    def _on_side(self, msg) -> None:
        self.sides.append(side_from_msg(msg))

    def _on_gate(self, msg) -> None:
        self.gate_commands.update([gate_margin(msg)])

    def _on_frame(self, msg) -> None:
        self.sim_time = stamp_to_seconds(msg.header.stamp)
        self.last_frame = (time.monotonic(), self.sim_time)
        self.first_frame = self.first_frame or self.last_frame

    def line_rtf(self, nodes_started: float) -> tuple[float, float] | None:
        """(sim s per wall s since the line's first frame, wall s from ``nodes_started`` to it); None before two
        frames."""
        if self.first_frame is None or self.last_frame[0] <= self.first_frame[0]:
            return None
        wall = self.last_frame[0] - self.first_frame[0]
        return (self.last_frame[1] - self.first_frame[1]) / wall, self.first_frame[0] - nodes_started

    def spin(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=max(0.0, deadline - time.monotonic()))

    def close(self) -> None:
        import rclpy

        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def describe_conditions(c: LineConditions) -> str:
    """A line's placement numbers in one phrase (help texts, the report's settings)."""
    return (f"yaw sd {c.yaw_sd_deg:g} deg (max {c.yaw_max_deg:g}), {c.blunt_fraction:g} blunt end first, lateral "
            f"sd {c.lateral_sd_m:g} m (max {c.lateral_max_m:g}), size x{c.scale_min:g}-{c.scale_max:g}")


def run_settings(args: argparse.Namespace, fillets: int | None) -> dict[str, object]:
    """The run's settings as report.md's table shows them; the recorder keeps them in the bag (``woody.run``)."""
    if args.fillets_per_minute is not None:
        spacing = f"{args.fillets_per_minute:g} fillets per minute per lane"
    else:
        spacing = "line_sim default" if args.spacing is None else args.spacing
    return {"lanes": args.lanes, "line speed (FPM)": args.speed_fpm,
            "stiffness mix k": ", ".join(f"{k:g}" for k in args.k), "meshes": args.meshes, "seed": args.seed,
            "fillets requested": fillets or f"{args.duration:g} s of spawning",
            "score": args.score or f"grader default ({SCORE_LINE})",
            "threshold": "grader default" if args.threshold is None else args.threshold,
            "side camera (Hz)": args.side_rate, "paced to wall clock": args.realtime, "top camera model": args.sensor,
            "top camera geometry": args.top_camera,
            "line conditions": f"{args.line}: {describe_conditions(args.conditions)}",
            "lane pitch (m)": args.lane_pitch_m, "in-lane spacing (m)": spacing,
            "speed change": (f"to {args.speed_change_fpm:g} FPM at {args.speed_change_at:g} s"
                             if args.speed_change_fpm else "none"),
            UNSCORED_DIVERTED: True, OUTSIDE_GRADED: args.grade_outside_calibration,
            "gate distance (m)": args.gate_distance, "namespace": args.namespace or "/",
            "physics": _physics_setting(args),
            CALIBRATED_SPEEDS: "..".join(f"{v:g}" for v in args.calibrated_speeds) if args.calibrated_speeds
            else "not recorded in the calibration"}


def run_checked(args: argparse.Namespace) -> int:
    """The line run of checked arguments; meshes, the domain and the output folder are checked before anything is
    written (`RunRefused`), and a stop signal before the nodes start ends it with nothing written (`RunInterrupted`).
    """
    STOP.install()
    fillets = args.fillets if args.fillets is not None or args.duration is not None else 12
    out = Path(args.out) if args.out else Path("bags") / datetime.now().strftime("run-%Y%m%d-%H%M%S")
    meshes, mesh_notes = _check_meshes(args.meshes)
    mesh_notes += _crowding_notes(meshes, args)
    _check_stop()
    try:
        lease = lease_domain(share=args.share_domain)
    except (DomainInUse, ValueError) as exc:
        raise RunRefused(str(exc)) from None
    monitor = None
    try:
        monitor = LineMonitor(lease.domain_id, args.namespace)
        if lease.exported and not args.share_domain:
            _refuse_foreign_nodes(monitor, lease.domain_id)
        _check_stop()
        lock = _claim_out(out, args.force)
        STOP.hangup_log = out / "logs" / HANGUP_LOG
        for line in mesh_notes + calibration_notes(args):
            print(f"woody run: {line}", file=sys.stderr, flush=True)
        try:
            return _run_line(args, fillets, out, monitor, mesh_notes)
        finally:
            lock.close()
    finally:
        if monitor is not None:
            monitor.close()
        lease.release()


def _check_stop() -> None:
    """`RunInterrupted` when a stop signal came before the nodes started: nothing to stop, nothing written."""
    if STOP.signum is not None:
        raise RunInterrupted(f"stopped by {STOP.name} before the line started; nothing written")


def calibration_notes(args: argparse.Namespace) -> list[str]:
    """A line per belt speed of the run (its --speed-fpm and --speed-change) outside the speeds the calibration's
    cuts were fitted on (the grader leaves fillets measured there unscored, or grades them on extrapolated cuts with
    --grade-outside-calibration), and one when its top camera is not the one they were fitted on."""
    speeds = dict.fromkeys((args.speed_fpm, args.speed_change_fpm or args.speed_fpm))
    notes = [uncalibrated_speed_note(fpm, args.calibrated_speeds, args.grade_outside_calibration) for fpm in speeds]
    notes.append(other_camera_note(args.top_camera, args.calibrated_camera))
    return [note for note in notes if note]


def _refuse_foreign_nodes(monitor: LineMonitor, domain_id: int, seconds: float = 4.0) -> None:
    """On an exported ROS_DOMAIN_ID other programs may already run: the line would mix with them.

    Discovery is given up to ``seconds`` (a loaded machine took more than 1.5 s to see a node that was there).
    """
    deadline = time.monotonic() + seconds
    foreign: list[str] = []
    while not foreign and time.monotonic() < deadline:
        monitor.spin(0.1)
        foreign = sorted({f"{ns.rstrip('/')}/{name}" for name, ns in monitor.node.get_node_names_and_namespaces()
                          if name != monitor.node.get_name()})
    if foreign:
        raise RunRefused(f"ROS_DOMAIN_ID={domain_id} (exported) already has nodes ({', '.join(foreign)}); the line "
                         "would mix with them. Unset ROS_DOMAIN_ID to get a private domain, or pass --share-domain")


def node_parameters(args: argparse.Namespace, fillets: int | None, out: Path) -> dict[str, dict[str, object]]:
    """Each node's parameters for checked arguments, in start order: recorder first (it must see every topic
    from the start), line_sim last (it waits for the vision nodes)."""
    camera_height = LineGeometry(**top_camera_preset(args.top_camera)).top_height
    # line_sim publishes its cameras reliable: a reliable subscription has lost fragments resent instead of
    # losing the frame (side passages beside two busy processes came whole 3 of 3 times, against 1 of 3)
    vision_params: dict[str, object] = {"use_sim_time": True, "lanes": args.lanes, "camera_height_m": camera_height,
                                        "image_qos": "reliable"}
    params = {
        "recorder": {"use_sim_time": True, "output": str(out / "line.mcap"),
                     "run_settings": json.dumps(run_settings(args, fillets)), **_recorded(args.namespace)},
        "segmenter": dict(vision_params, lane_pitch_m=args.lane_pitch_m,
                          **({} if args.sensor == "ideal" else REAL_CAMERA_FILTERS),
                          **({"depth_unit_m": load_camera(args.top_camera).depth_unit_m}
                             if is_camera_file(args.top_camera) else {})),
        "grader": _grader_params(args, vision_params),
        "reject_gate": {"use_sim_time": True, "lanes": args.lanes, "line_speed_fpm": args.speed_fpm,
                        "gate_distance_m": [args.gate_distance], "divert_unscored": True},
        **({"foxglove_view": {"use_sim_time": True, "port": args.live}} if args.live is not None else {}),
        "line_sim": _sim_params(args, fillets),
    }
    for name, given in args.vision_setup.items():  # woody camera setup's values win over the simulator's
        params[name].update(given)
    return params


def _start_nodes(args: argparse.Namespace, fillets: int | None, out: Path, domain_id: int) -> list[NodeProcess]:
    """The nodes of :func:`node_parameters`, started in its order; line_sim and the grader load --calibration
    first, so the parameters given here win."""
    nodes: list[NodeProcess] = []
    for name, params in node_parameters(args, fillets, out).items():
        calibration = ("--ros-args", "--params-file", args.calibration) if name in ("line_sim", "grader") else ()
        nodes.append(NodeProcess(name, params, domain_id=domain_id, log_dir=out / "logs", extra_args=calibration,
                                 namespace=args.namespace))
    return nodes


def _sim_params(args: argparse.Namespace, fillets: int | None) -> dict[str, object]:
    """line_sim's parameters: the line, its preset and the placement options given, the crowding, the speed."""
    params: dict[str, object] = {
        "lanes": args.lanes, "line_speed_fpm": args.speed_fpm, "k_values": [float(k) for k in args.k],
        "meshes": args.meshes, "seed": args.seed, "fillets": fillets or 0, "spawn_duration_s": args.duration or 0.0,
        "realtime": args.realtime, "side_rate_hz": args.side_rate, "wait_for_subscribers": 2,
        "wait_for_side_subscribers": 2, "wait_for_recorder": "recorder",
        "max_lead_s": MAX_LEAD_S, "top_camera": args.top_camera, "sensor": args.sensor, "line": args.line,
        "lane_pitch_m": args.lane_pitch_m, **{name: float(value) for name, value in args.placement.items()},
    }
    if args.spacing is not None:
        params["spawn_spacing_m"] = float(args.spacing)
    if args.fillets_per_minute is not None:
        params["fillets_per_minute"] = float(args.fillets_per_minute)
    if args.speed_change_fpm:
        params.update(speed_change_fpm=float(args.speed_change_fpm), speed_change_at_s=float(args.speed_change_at))
    return {**params, **_physics_params(args)}


def _physics_setting(args: argparse.Namespace) -> str:
    """The run's physics as report.md names it: the line_sim parameters its options set, else line_sim's own."""
    return ", ".join(f"{name} {value:g}" for name, value in _physics_params(args).items()) or "line_sim default"


def _physics_params(args: argparse.Namespace) -> dict[str, object]:
    """line_sim's physics parameters the options gave: its workers, their recycling, the paper's chain."""
    params: dict[str, object] = {}
    if args.physics_workers is not None:
        params["physics_workers"] = args.physics_workers
    if args.physics_recycle is not None:
        params["physics_recycle_fillets"] = args.physics_recycle
    if args.paper_physics:
        params.update(segments=PAPER_SEGMENTS, physics_rate_hz=PAPER_PHYSICS_RATE_HZ)
    return params


def _grader_params(args: argparse.Namespace, vision_params: dict[str, object]) -> dict[str, object]:
    """The grader's: the score it grades and, with --threshold, a constant reject cut on that score."""
    params = dict(vision_params, grade_outside_calibration=args.grade_outside_calibration)
    if args.score is not None:
        params["score"] = args.score
    if args.threshold is not None:
        if (args.score or SCORE_LINE) == SCORE_LINE:
            params["line_threshold"] = [float(args.threshold)] + [0.0] * (len(CUT_TERMS) - 1)  # constant
        else:
            params["threshold"] = float(args.threshold)
    return params


def _recorded(namespace: str) -> dict[str, str]:
    """Recorder parameters that keep a namespaced line's bag to its own topics (and clock)."""
    ns = namespace.strip("/")
    return {"topic_regex": f"^/{ns}/"} if ns else {}


def _stop_nodes(nodes: list[NodeProcess]) -> None:
    """SIGINT to every node at once (only once: a second one cuts a node's summary short), the recorder last."""
    for node in nodes:
        if node.name != "recorder":
            node.signal(signal.SIGINT)
    for node in nodes:
        if node.name != "recorder":
            node.stop(timeout=10.0)
    for node in nodes:
        if node.name == "recorder":
            node.stop(timeout=30.0)


def _watch(monitor: LineMonitor, nodes: list[NodeProcess], fillets: int | None, args: argparse.Namespace,
           cpu: CpuAccounting) -> str | NodeProcess | None:
    """Show progress until the line is done; why it stopped early (INTERRUPTED, a time-out, a node that died),
    else None."""
    from tqdm import tqdm

    wall_start = time.monotonic()
    bar = tqdm(total=fillets or None, unit="fillet", desc="graded", dynamic_ncols=True, mininterval=1.0,
               file=sys.stderr, disable=None if sys.stderr.isatty() else True)
    last_line, done_since = 0.0, None
    try:
        while True:
            monitor.spin(0.25)
            cpu.sample()
            graded = len(monitor.verdicts)
            elapsed = time.monotonic() - wall_start
            status = "; ".join([f"spawned {len(monitor.spawns)}, sim {monitor.sim_time:.1f} s, "
                                f"rtf {monitor.sim_time / max(elapsed, 1e-9):.2f}x", *monitor.holding_up()])
            if bar.disable and time.monotonic() - last_line >= 10.0:  # not a terminal: a plain line now and then
                print(f"graded {graded}/{fillets or '?'} fillets, {status}", file=sys.stderr, flush=True)
                last_line = time.monotonic()
            bar.update(min(graded, bar.total or graded) - bar.n)
            bar.set_postfix_str(status, refresh=False)
            if STOP.signum is not None:
                return INTERRUPTED
            dead = [n for n in nodes if not n.alive()]
            if dead:
                return dead[0]
            if elapsed > args.timeout:
                return f"timed out after {args.timeout:.0f} s of wall time"
            if _finished(monitor, fillets, args):
                done_since = done_since or time.monotonic()
                if time.monotonic() - done_since > 1.0:
                    return None
    finally:
        bar.close()


def _run_line(args: argparse.Namespace, fillets: int | None, out: Path, monitor: LineMonitor,
              mesh_notes: list[str]) -> int:
    """Start the nodes, watch the line, stop the nodes however the run ends; write what was graded, or set a run
    that graded nothing aside; the exit code."""
    print(f"woody run: ROS_DOMAIN_ID={monitor.domain_id}, output {out}/", flush=True)
    for line in _shm_notes():
        print(f"woody run: {line}", flush=True)
    nodes: list[NodeProcess] = []
    cpu = reason = None
    try:
        nodes = _start_nodes(args, fillets, out, monitor.domain_id)
        if args.live is not None:
            where = f"ws://127.0.0.1:{args.live}" if args.live else f"the port {out / 'logs/foxglove_view.log'} names"
            print(f"live view: Foxglove → Open connection → Foxglove WebSocket → {where} (layout: "
                  "docs/foxglove-layout.json)", file=sys.stderr, flush=True)
        cpu = CpuAccounting({"woody run": os.getpid(), **{n.name: n.process.pid for n in nodes}})
        wall_start = time.monotonic()
        reason = _watch(monitor, nodes, fillets, args, cpu)
    finally:
        if cpu is not None:
            cpu.sample()
            wall = time.monotonic() - wall_start
        _stop_nodes(nodes)
    failed = reason is not None and not monitor.verdicts
    bag = (_set_aside(out, nodes) if failed else out) / "line.mcap"
    recorder = next((n for n in nodes if n.name == "recorder"), None)
    problems = [_reason_line(reason)] if reason is not None and reason is not recorder else []
    recorder_failed = recorder is not None and bool(recorder.returncode or reason is recorder)
    if recorder_failed:
        problems.append(recorder_failure(recorder.log_path) or recorder_problem(recorder.returncode, bag))
    if failed:
        problems.append(f"nothing was graded: the run's bag and logs are in {bag.parent}/, and the same command "
                        "can run again")
    else:
        problems += _write_outputs(args, fillets, out, monitor, mesh_notes)
    if cpu is not None and not failed:
        _print_pace(monitor, cpu, wall, wall_start)
    for problem in problems:
        print(f"woody run: {problem}", file=sys.stderr, flush=True)
    if recorder_failed or reason not in (None, INTERRUPTED) or any(p.startswith(OUTPUTS_UNWRITTEN) for p in problems):
        return 1
    return 128 + STOP.signum if reason == INTERRUPTED else 0


def _reason_line(reason: str | NodeProcess) -> str:
    """What ended the run early, as woody run says it."""
    if isinstance(reason, NodeProcess):
        return (f"node '{reason.name}' exited with code {reason.returncode}; last lines of {reason.log_path}:\n"
                f"{reason.log_tail()}")
    if reason != INTERRUPTED:
        return reason
    terminal = " (the terminal closed)" if STOP.signum == signal.SIGHUP else ""
    return f"stopped by {STOP.name}{terminal}: the nodes were stopped and what was graded is kept"


def recorder_problem(code: int | None, bag: Path) -> str:
    """The one line for a recorder that ended on its own or failed (``code`` non-zero, negative for a signal): its
    exit code and the command that rescues the bag."""
    how = f"code {code}"
    if code is not None and code < 0 and -code in signal.valid_signals():
        how += f" ({signal.Signals(-code).name})"
    rescued = bag.with_name(f"{bag.stem}-recovered{bag.suffix}")
    return (f"recorder exited with {how}: {bag} may not be finalised; rescue it with "
            f"`woody bag recover {bag} {rescued}`")


def _set_aside(out: Path, nodes: list[NodeProcess]) -> Path:
    """Move a run's bag and logs into ``out/failed/`` (replacing an earlier one there; the nodes' log paths
    follow), so a run that graded nothing leaves nothing that blocks the same --out and loses nothing."""
    failed = out / FAILED_DIR
    shutil.rmtree(failed, ignore_errors=True)
    failed.mkdir()
    for name in ("line.mcap", "logs"):
        if (out / name).exists():
            (out / name).rename(failed / name)
    for node in nodes:
        node.log_path = failed / "logs" / node.log_path.name
    return failed


def _print_pace(monitor: LineMonitor, cpu: CpuAccounting, wall: float, wall_start: float) -> None:
    print(f"sim {monitor.sim_time:.1f} s in {wall:.1f} s wall: rtf {monitor.sim_time / max(wall, 1e-9):.2f}x")
    line = monitor.line_rtf(wall_start)
    if line is not None:
        print(f"the line itself, after {line[1]:.1f} s of node start-up: rtf {line[0]:.2f}x")
    print(cpu.summary(wall))


def _write_outputs(args: argparse.Namespace, fillets: int | None, out: Path, monitor: LineMonitor,
                   mesh_notes: list[str]) -> list[str]:
    """Print the verdict table, write verdicts.csv, report.md and the fillet pictures; the lines woody run adds on
    stderr: messages the recorder lost, and `OUTPUTS_UNWRITTEN` when --out takes no more (a full disk: the table
    printed first is then the record of what was graded)."""
    records = line_records(out / "line.mcap", monitor)
    rows = records.rows()
    info = dict(run_settings(args, fillets))
    info.update({"fillets spawned": len(records.spawns), "verdicts": len(records.verdicts),
                 "gate commands": len(records.gated or ()), "sim time (s)": f"{monitor.sim_time:.1f}"})
    recording, lost = recording_summary(out / "line.mcap")
    info[RECORDING] = recording
    problems = [f"recorder: {lost}: {LOST_NOTE}"] if lost else []
    pictures, notes = [], list(mesh_notes) + problems
    print(verdict_table(rows, divert_unscored=unscored_diverted(info)))
    print(f"\n{diversion_summary(rows, unscored_diverted(info))}")
    csv_path = None
    try:
        csv_path = write_csv(rows, out / "verdicts.csv")
        if (out / "line.mcap").exists():
            try:
                pictures = write_fillet_pictures(out / "line.mcap", out)
            except Exception as exc:  # a bag the recorder left cut short still gives the report, without pictures
                notes.append(f"no fillet pictures: {exc}")
        report = build_report(rows, out, title="woody line run", run_info=info, notes=notes, extra=pictures)
    except OSError as exc:
        kept = "verdicts.csv written, report.md not" if csv_path else "neither verdicts.csv nor report.md written"
        return problems + [f"{OUTPUTS_UNWRITTEN} {out}/ ({exc.strerror or exc}): {kept}; the table above is what "
                           "was graded"]
    print(f"bag: {out / 'line.mcap'} ({recording})\nverdicts: {csv_path}\nreport: {report}\n"
          f"node logs: {out / 'logs'}/")
    for line in mesh_notes + calibration_notes(args):
        print(line)
    return problems


def line_records(bag: Path, monitor: LineMonitor) -> LineRecords:
    """What the line published, from the bag (the record of what the nodes sent, read after they stopped) together
    with what this process heard live (a message the recorder lost): every published verdict, once."""
    live = LineRecords(monitor.spawns, monitor.verdicts, monitor.sides, monitor.gate_commands)
    try:
        recorded, _ = records_from_bag(bag)
    except (BagError, OSError, ValueError):  # no bag, or nothing readable in it: the live record is all there is
        return live
    return recorded.merged(live)


def recording_summary(bag: Path) -> tuple[str, str | None]:
    """What the bag holds, for the terminal and report.md ("5133 messages, no message lost"), and what the recorder
    lost per topic, or every topic it received nothing on when that includes the line's /clock, published all run
    long (None when nothing was lost or the bag does not say)."""
    try:
        summary = bag_summary(bag)
    except BagError as exc:
        return str(exc), None
    losses = recorded_losses(summary["metadata"])
    unrecorded = unrecorded_topics(summary)
    missed = [losses_text(losses)] if losses else []
    if "/clock" in unrecorded:
        missed.append(f"nothing recorded on {', '.join(unrecorded)}")
    return recording_text(summary), "; ".join(missed) or None


def _shm_notes() -> list[str]:
    """Remove the Fast DDS shared memory that killed processes left (woody_common.dds_shm); a line saying so."""
    removed, freed = remove_stale()
    return [f"removed {removed} Fast DDS shared-memory files ({freed / 1e6:.0f} MB) left by processes that were "
            "killed"] if removed else []


def _finished(monitor: LineMonitor, fillets: int | None, args: argparse.Namespace) -> bool:
    """Every spawned fillet has a verdict, or has had ample sim time to get one."""
    if fillets and len(monitor.spawns) < fillets:
        return False
    if not fillets and monitor.sim_time < (args.duration or 0.0):
        return False
    if not monitor.spawns:
        return False
    last = max(s.expected_crossing for s in monitor.spawns)
    watched = watched_lane(args.lanes) if args.side_rate > 0 else None
    waiting = {v.fillet_id for v in monitor.verdicts if v.lane == watched} - {s.fillet_id for s in monitor.sides}
    if len(monitor.verdicts) >= len(monitor.spawns) and monitor.sim_time > last + MATCH_TOLERANCE_S and not waiting:
        return True  # not before the last fillet's verdict is due (a track split in two publishes two verdicts),
        # nor before the watched lane's side metrics are in
    return monitor.graded_time() > last + 4.0  # a grader held up still publishes what it owes
