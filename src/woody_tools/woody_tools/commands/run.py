"""`woody run`: the whole line as separate processes on a private ROS domain (:mod:`woody_tools.line_run`).

Starts recorder, segmenter, grader, reject_gate and line_sim, watches ground
truth, verdicts and /clock from this process to show progress, stops
everything when every fillet is graded (or on Ctrl-C, or when a node dies),
and leaves the bag, verdicts.csv and report.md in the output folder.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from pathlib import Path

import yaml

from woody_common.calibration import ENV_VAR, resolve_calibration, resolved_calibration
from woody_common.line import (
    CLASS_K,
    LANE_PITCH_M,
    MAX_FILLETS,
    MAX_LANES,
    MAX_SEED,
    MAX_SIDE_RATE_HZ,
    MAX_SPAWN_DURATION_S,
    MAX_SPAWN_SPACING_M,
    MIN_SPAWN_SPACING_M,
    REFERENCE_SPEED_FPM,
    SPEED_RANGE_FPM,
    check_lane_pitch,
    fpm_to_mps,
    max_fillets_per_minute,
    physics_worker_limit,
)
from woody_sim.camera_description import is_camera_file, load_camera
from woody_sim.line_conditions import LINE_PRESETS, MAX_LATERAL_M, MAX_YAW_DEG, SCALE_RANGE, LineConditions
from woody_sim.meshes import MAX_YAW_SD_DEG
from woody_sim.sensor_model import PRESETS
from woody_tools import arguments, line_run
from woody_tools.line_run import RunInterrupted, RunRefused, describe_conditions
from woody_tools.processes import STOP
from woody_vision.gate_timing import GATE_DISTANCE_M, GATE_DISTANCE_RANGE_M
from woody_vision.grader_core import SCORES
from woody_vision.grading import THRESHOLD_RANGE

"""Largest constant reject cut accepted (the grader's own limit on ``threshold``)."""
PLACEMENT_OPTIONS = (  # (option, LineConditions field, lowest, highest, unit)
    ("--yaw-sd", "yaw_sd_deg", 0.0, MAX_YAW_SD_DEG, "deg"),
    ("--yaw-max", "yaw_max_deg", 0.0, MAX_YAW_DEG, "deg"),
    ("--blunt-fraction", "blunt_fraction", 0.0, 1.0, ""),
    ("--lateral-sd", "lateral_sd_m", 0.0, MAX_LATERAL_M, "m"),
    ("--lateral-max", "lateral_max_m", 0.0, MAX_LATERAL_M, "m"),
)
"""The placement options of a messy line, each overriding the --line preset's value (line_sim's parameters)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--lanes", type=int, default=3, help="lanes across the belt, 1-6 (default 3)")
    parser.add_argument("--speed-fpm", type=float, default=REFERENCE_SPEED_FPM,
                        help=f"line speed in feet per minute, anywhere in {SPEED_RANGE_FPM[0]:g}.."
                             f"{SPEED_RANGE_FPM[1]:g} (default 100; commercial lines run 90-140); a speed outside "
                             "those the calibration's cuts were fitted on is warned about at the start, at the end "
                             "and in report.md")
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--fillets", type=int, default=None, help="total fillets to spawn (default 12)")
    group.add_argument("--duration", type=float, default=None, help="sim seconds of spawning instead of a count")
    parser.add_argument("--k", type=float, nargs="+", default=list(CLASS_K),
                        help="stiffness values to mix, N*m/rad (default: 0 normal, 100 woody)")
    parser.add_argument("--meshes", default="builtin",
                        help="builtin, generated:N[:SEED], a folder of meshes; comma-combinable (default builtin)")
    parser.add_argument("--seed", type=int, default=7, help="seed of the fillet mix (default 7)")
    parser.add_argument("--out", default=None, help="output folder (default bags/run-<time>)")
    parser.add_argument("--realtime", action="store_true", help="pace the simulation to the wall clock")
    parser.add_argument("--side-rate", type=float, default=60.0, help="side camera frame rate, Hz (default 60)")
    arguments.add_top_camera(parser, "a file gives resolution, intrinsics, distortion, mount and timing, and the "
                                     "error model unless --sensor is given")
    parser.add_argument("--calibration", default=None, metavar="FILE",
                        help="calibration file given to line_sim and the grader as a ROS params file "
                             f"(default ${ENV_VAR}, else the installed config/calibration.yaml)")
    parser.add_argument("--vision-setup", dest="vision_setup_file", default=None, metavar="PARAMS.yaml",
                        help="the parameters `woody camera setup` wrote from a recording of this camera: the "
                             "segmenter and grader take their lanes, pitch, height and edge from it, and line_sim "
                             "puts its mount on tf_static, instead of the simulator's own values")
    parser.add_argument("--timeout", type=float, default=1800.0, help="wall-clock limit in seconds (default 1800)")
    parser.add_argument("--sensor", default=None, choices=sorted(PRESETS),
                        help="top camera error model (docs/sensors.md); default: the camera file's, else ideal")
    parser.add_argument("--live", type=int, nargs="?", const=8765, default=None, metavar="PORT",
                        help="watch the line in Foxglove while it runs: serve it on ws://127.0.0.1:PORT (default "
                             "8765; the foxglove_view node, docs/foxglove.md)")
    parser.add_argument("--namespace", default="", metavar="NS",
                        help="run the line under NS (topics NS/..., sim clock NS/clock), so several lines share a "
                             "ROS domain; default: the root namespace")
    parser.add_argument("--force", action="store_true",
                        help="overwrite a run already in --out (a run that graded nothing leaves its bag and logs "
                             "in --out/failed/ and needs no --force)")
    parser.add_argument("--share-domain", action="store_true",
                        help="run on an exported ROS_DOMAIN_ID even when another woody run holds it (they mix)")
    _add_line_arguments(parser)
    _add_grading_arguments(parser)
    _add_physics_arguments(parser)


def _add_physics_arguments(parser: argparse.ArgumentParser) -> None:
    physics = parser.add_argument_group("physics (line_sim's parameters of the same names)")
    arguments.add_physics_workers(physics, "")
    physics.add_argument("--physics-recycle", type=int, default=None, metavar="N",
                         help="replace each physics worker with a fresh process after N fillets, so that a line "
                              "running for hours keeps its memory flat (needs --physics-workers >= 1)")
    physics.add_argument("--paper-physics", action="store_true",
                         help="simulate the paper's chain (40 slices at 480 Hz) instead of the default 24 slices at "
                              "360 Hz (docs/physics.md)")


def _add_line_arguments(parser: argparse.ArgumentParser) -> None:
    """How untidy the line is (woody_sim.line_conditions) and how crowded: line_sim's placement parameters."""
    presets = "; ".join(f"{name}: {describe_conditions(c)}" for name, c in LINE_PRESETS.items())
    line = parser.add_argument_group("line conditions", "each fillet is placed by its own draw, seeded by --seed "
                                     "and its spawn index; an option given here wins over the --line preset")
    line.add_argument("--line", default="tidy", metavar="PRESET",
                      help=f"line conditions preset, {'|'.join(LINE_PRESETS)} (default tidy). {presets}")
    line.add_argument("--yaw-sd", type=float, default=None, metavar="DEG",
                      help=f"per-fillet turn on the belt: sd of a normal draw truncated at --yaw-max, "
                           f"0..{MAX_YAW_SD_DEG:g} (0: straight)")
    line.add_argument("--yaw-max", type=float, default=None, metavar="DEG",
                      help=f"largest turn, 0..{MAX_YAW_DEG:g} (0: 2 x --yaw-sd)")
    line.add_argument("--blunt-fraction", type=float, default=None, metavar="F",
                      help="fraction of fillets sent blunt end first, 0..1")
    line.add_argument("--lateral-sd", type=float, default=None, metavar="M",
                      help=f"offset of a fillet's centre across its lane: sd of a normal draw truncated at "
                           f"--lateral-max, 0..{MAX_LATERAL_M:g} m")
    line.add_argument("--lateral-max", type=float, default=None, metavar="M",
                      help=f"largest lateral offset, 0..{MAX_LATERAL_M:g} m and at most half the lane pitch "
                           "(0: 2 x --lateral-sd)")
    line.add_argument("--scale", default=None, metavar="MIN,MAX",
                      help=f"size factor drawn uniform in MIN..MAX, within {SCALE_RANGE[0]:g}..{SCALE_RANGE[1]:g}; "
                           "a fillet's mass follows its volume (x s^3)")
    line.add_argument("--lane-pitch", type=float, default=None, metavar="M",
                      help=f"distance between lane centres, given to line_sim and the segmenter (default "
                           f"{LANE_PITCH_M:g} m); small enough and neighbouring fillets touch side by side")
    line.add_argument("--spacing", type=float, default=None, metavar="M",
                      help=f"belt distance between consecutive fillets of a lane, {MIN_SPAWN_SPACING_M:g}.."
                           f"{MAX_SPAWN_SPACING_M:g} m (default line_sim's 0.45); a fillet's length + 0.02 leaves a "
                           "2 cm gap")
    line.add_argument("--fillets-per-minute", type=float, default=None, metavar="N",
                      help=f"spawn rate per lane instead of --spacing; at most the rate that keeps fillets "
                           f"{MIN_SPAWN_SPACING_M:g} m apart at the line speed")
    line.add_argument("--speed-change", default=None, metavar="FPM@SECONDS",
                      help="the belt changes to FPM at SECONDS of sim time; every fillet on it follows")


def _add_grading_arguments(parser: argparse.ArgumentParser) -> None:
    grading = parser.add_argument_group("grading")
    grading.add_argument("--score", default=None, metavar="SCORE",
                         help="what the grader grades: line (line_phi against cuts that follow the measured speed "
                              "and leading end, three-class grade; the grader's default) or paper (the paper's Φ "
                              "against one threshold)")
    grading.add_argument("--threshold", type=float, default=None, metavar="X",
                         help="a constant reject cut on the score in use (line: line_threshold [X, 0, 0, 0, 0]; paper: "
                              "threshold X); default the calibrated cuts of --calibration")
    grading.add_argument("--grade-outside-calibration", action="store_true",
                         help="grade fillets measured outside the speeds, turns and lengths the calibration's cuts "
                              "were fitted on (the grader's grade_outside_calibration) on extrapolated cuts; by "
                              "default they are unscored, so the gate diverts them")
    grading.add_argument("--gate-distance", type=float, default=GATE_DISTANCE_M, metavar="M",
                         help="distance from the roller edge to every lane's diverter, m (reject_gate's "
                              f"gate_distance_m; default {GATE_DISTANCE_M:g}): how long a verdict has to reach the "
                              "gate")


def _validate(args: argparse.Namespace) -> None:
    low, high = SPEED_RANGE_FPM
    if not 1 <= args.lanes <= MAX_LANES:
        raise RunRefused(f"--lanes must be 1..{MAX_LANES}, got {args.lanes}")
    if not low <= args.speed_fpm <= high:
        raise RunRefused(f"--speed-fpm must be in [{low:g}, {high:g}], got {args.speed_fpm}")
    if args.fillets is not None and not 1 <= args.fillets <= MAX_FILLETS:
        raise RunRefused(f"--fillets must be 1..{MAX_FILLETS}, got {args.fillets}")
    if not 0 <= args.seed <= MAX_SEED:
        raise RunRefused(f"--seed must be 0..{MAX_SEED}, got {args.seed}")
    if args.duration is not None and not 0.0 < args.duration <= MAX_SPAWN_DURATION_S:
        raise RunRefused(f"--duration must be in (0, {MAX_SPAWN_DURATION_S:g}] sim seconds, got {args.duration:g}")
    if not 0.0 <= args.side_rate <= MAX_SIDE_RATE_HZ:
        raise RunRefused(f"--side-rate must be in [0, {MAX_SIDE_RATE_HZ:g}] Hz (0: no side camera), "
                         f"got {args.side_rate:g}")
    if not all(0 <= k < math.inf for k in args.k):
        raise RunRefused(f"--k values must be finite and >= 0, got {' '.join(f'{k:g}' for k in args.k)}")
    if args.namespace and not re.fullmatch(r"/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*", args.namespace):
        raise RunRefused(f"--namespace must be a ROS name like /line2, got '{args.namespace}'")
    if args.live is not None and not 0 <= args.live <= 65535:
        raise RunRefused(f"--live PORT must be 0..65535 (0: any free port), got {args.live}")
    _validate_line(args)
    _validate_crowding(args)
    _validate_physics(args)
    _validate_grading(args)
    _validate_calibration(args)
    _validate_top_camera(args)
    _validate_vision_setup(args)


def _validate_physics(args: argparse.Namespace) -> None:
    cores = physics_worker_limit()
    if args.physics_workers is not None and not 0 <= args.physics_workers <= cores:
        raise RunRefused(f"--physics-workers must be 0..{cores} (this machine's cores), got {args.physics_workers}")
    if args.physics_recycle is not None:
        if args.physics_recycle < 1:
            raise RunRefused(f"--physics-recycle must be >= 1 fillets, got {args.physics_recycle}")
        if args.physics_workers == 0:
            raise RunRefused("--physics-recycle needs --physics-workers >= 1: only a worker process can be replaced")


VISION_SETUP_NODES = ("segmenter", "grader", "line_sim")
"""The nodes a ``woody camera setup`` parameters file sets."""


def _validate_vision_setup(args: argparse.Namespace) -> None:
    """Read ``--vision-setup`` into ``args.vision_setup`` (node name -> its parameters; empty without it), refusing
    a file that is not a setup of this line."""
    args.vision_setup = {}
    if args.vision_setup_file is None:
        return
    try:
        loaded = yaml.safe_load(Path(args.vision_setup_file).read_text())
        params = {name: dict(loaded[f"/**/{name}"]["ros__parameters"]) for name in VISION_SETUP_NODES}
    except (OSError, yaml.YAMLError, KeyError, TypeError) as exc:
        raise RunRefused(f"--vision-setup {args.vision_setup_file}: not a woody camera setup parameters file "
                         f"({type(exc).__name__}: {exc})") from None
    found = params["segmenter"].get("lanes")
    if found != args.lanes:
        raise RunRefused(f"--vision-setup {args.vision_setup_file} found {found} lanes; the line has --lanes "
                         f"{args.lanes}")
    args.vision_setup = params


def _validate_top_camera(args: argparse.Namespace) -> None:
    """A top camera preset, or a description file made absolute for the nodes; ``--sensor`` not given becomes the
    file's error model (else ideal)."""
    problem = arguments.top_camera_problem(args)
    if problem:
        raise RunRefused(problem)
    if args.sensor is None:
        args.sensor = load_camera(args.top_camera).sensor if is_camera_file(args.top_camera) else "ideal"


def _validate_calibration(args: argparse.Namespace) -> None:
    """Resolve ``--calibration`` to the file the nodes are given, refusing one that is not a calibration; sets
    ``args.calibrated_speeds``, the line speeds its cuts were fitted on (None when it does not record them), and
    ``args.calibrated_camera``, the top camera they were fitted on."""
    args.calibration = str(resolve_calibration(args.calibration))
    try:
        calibration = resolved_calibration(args.calibration)
    except ValueError as exc:
        raise RunRefused(str(exc)) from None
    args.calibrated_speeds, args.calibrated_camera = calibration.speed_range_fpm, calibration.top_camera


def _validate_line(args: argparse.Namespace) -> None:
    """The placement options against their ranges; sets ``args.placement`` (the options given, as line_sim's
    parameters) and ``args.conditions`` (the line they make with the preset)."""
    if args.line not in LINE_PRESETS:
        raise RunRefused(f"--line must be one of {'|'.join(LINE_PRESETS)}, got '{args.line}'")
    given: dict[str, float] = {}
    for option, field, low, high, unit in PLACEMENT_OPTIONS:
        value = getattr(args, option[2:].replace("-", "_"))
        if value is None:
            continue
        if not low <= value <= high:
            raise RunRefused(f"{option} must be within {low:g}..{high:g}{' ' + unit if unit else ''}, got {value:g}")
        given[field] = value
    if args.scale is not None:
        given["scale_min"], given["scale_max"] = _scale_range(args.scale)
    preset = LINE_PRESETS[args.line]
    values = {field: getattr(preset, field) for field in LineConditions.__dataclass_fields__}
    values.update(given)
    for field in ("yaw_max_deg", "lateral_max_m"):  # 0 means 2 sd, as in line_sim
        values[field] = values[field] or None
    try:
        args.conditions = LineConditions(**values)
    except ValueError as exc:
        raise RunRefused(f"--line {args.line} with the options given: {exc}") from None
    args.placement = given


def _scale_range(text: str) -> tuple[float, float]:
    """``--scale MIN,MAX`` within SCALE_RANGE, MIN <= MAX."""
    low, high = SCALE_RANGE
    try:
        smallest, largest = (float(part) for part in text.split(","))
    except ValueError:
        smallest = largest = float("nan")
    if not low <= smallest <= largest <= high:
        raise RunRefused(f"--scale must be MIN,MAX with {low:g} <= MIN <= MAX <= {high:g}, got '{text}'")
    return smallest, largest


def _validate_crowding(args: argparse.Namespace) -> None:
    """Lane pitch, in-lane spacing or spawn rate, and the speed change; sets ``args.lane_pitch_m`` and
    ``args.speed_change_fpm``/``args.speed_change_at`` (0, 0 without a change)."""
    pitch = LANE_PITCH_M if args.lane_pitch is None else args.lane_pitch
    try:
        args.lane_pitch_m = check_lane_pitch(args.lanes, pitch)
    except ValueError as exc:
        raise RunRefused(f"--lane-pitch: {exc}") from None
    lateral = args.conditions.lateral_max_m
    if lateral > pitch / 2 + 1e-12:
        raise RunRefused(f"lateral offsets up to {lateral:g} m would move fillets out of lanes {pitch:g} m apart: "
                         f"--lateral-max at most {pitch / 2:g} m")
    if args.spacing is not None and args.fillets_per_minute is not None:
        raise RunRefused("--spacing and --fillets-per-minute both set the in-lane spacing: give one")
    if args.spacing is not None and not MIN_SPAWN_SPACING_M <= args.spacing <= MAX_SPAWN_SPACING_M:
        raise RunRefused(f"--spacing must be within {MIN_SPAWN_SPACING_M:g}..{MAX_SPAWN_SPACING_M:g} m (below "
                         f"{MIN_SPAWN_SPACING_M:g} m every fillet overlaps the next), got {args.spacing:g}")
    args.speed_change_fpm, args.speed_change_at = _speed_change(args.speed_change)
    rate = args.fillets_per_minute
    for fpm in dict.fromkeys((args.speed_fpm, args.speed_change_fpm or args.speed_fpm)):
        top = max_fillets_per_minute(fpm_to_mps(fpm))
        if rate is not None and not 0.0 < rate <= top * (1 + 1e-12):
            raise RunRefused(f"--fillets-per-minute must be in (0, {top:.1f}] at {fpm:g} FPM (fillets at least "
                             f"{MIN_SPAWN_SPACING_M:g} m apart), got {rate:g}")


def _speed_change(text: str | None) -> tuple[float, float]:
    """``--speed-change FPM@SECONDS`` as (FPM, sim s); (0, 0) without one."""
    if text is None:
        return 0.0, 0.0
    try:
        return arguments.speed_change(text)
    except ValueError as exc:
        raise RunRefused(f"--speed-change: {exc}") from None


def _validate_grading(args: argparse.Namespace) -> None:
    if args.score is not None and args.score not in SCORES:
        raise RunRefused(f"--score must be one of {'|'.join(SCORES)}, got '{args.score}'")
    low, high = THRESHOLD_RANGE
    if args.threshold is not None and not low <= args.threshold <= high:
        raise RunRefused(f"--threshold must be in [{low:g}, {high:g}], got {args.threshold:g}")
    low, high = GATE_DISTANCE_RANGE_M
    if not low <= args.gate_distance <= high:
        raise RunRefused(f"--gate-distance must be in [{low:g}, {high:g}] m, got {args.gate_distance:g}")


def checked(args: argparse.Namespace) -> argparse.Namespace:
    """``args`` validated and resolved (the line's conditions, lane pitch, speed change) for
    :func:`woody_tools.line_run.run_checked`; `RunRefused` names the first bad option in one line."""
    _validate(args)
    return args


def run(args: argparse.Namespace) -> int:
    try:
        return line_run.run_checked(checked(args))
    except RunRefused as exc:
        print(f"woody run: {exc}", file=sys.stderr)
        return 2
    except RunInterrupted as exc:
        print(f"woody run: {exc}", file=sys.stderr)
        return 128 + STOP.signum
