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

from woody_common.calibration import DEFAULT_PATH as CALIBRATION_PATH
from woody_common.line import MAX_SIDE_RATE_HZ, MAX_SPAWN_DURATION_S, SPEED_RANGE_FPM
from woody_sim.line_geometry import TOP_CAMERA_PRESETS
from woody_sim.sensor_model import PRESETS
from woody_tools import arguments, line_run
from woody_tools.line_run import RunRefused


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
    parser.add_argument("--top-camera", default="default", choices=sorted(TOP_CAMERA_PRESETS),
                        help="top camera geometry: default (672x376, 0.75 m) or paper (the seed system's 960x696, "
                             "86.6 deg, 0.33 m)")
    arguments.add_yaw_sd(parser, "line_sim's yaw_sd_deg")
    parser.add_argument("--calibration", default=str(CALIBRATION_PATH),
                        help="calibration file given to line_sim and the grader as a ROS params file "
                             "(default config/calibration.yaml)")
    parser.add_argument("--timeout", type=float, default=1800.0, help="wall-clock limit in seconds (default 1800)")
    parser.add_argument("--sensor", default="ideal", choices=sorted(PRESETS),
                        help="top camera error model (docs/sensors.md); default ideal")
    parser.add_argument("--namespace", default="", metavar="NS",
                        help="run the line under NS (topics NS/..., sim clock NS/clock), so several lines share a "
                             "ROS domain; default: the root namespace")
    parser.add_argument("--force", action="store_true", help="overwrite a run already in --out")
    parser.add_argument("--share-domain", action="store_true",
                        help="run on an exported ROS_DOMAIN_ID even when another woody run holds it (they mix)")


def _validate(args: argparse.Namespace) -> None:
    low, high = SPEED_RANGE_FPM
    if not 1 <= args.lanes <= 6:
        raise RunRefused(f"--lanes must be 1..6, got {args.lanes}")
    if not low <= args.speed_fpm <= high:
        raise RunRefused(f"--speed-fpm must be in [{low:g}, {high:g}], got {args.speed_fpm}")
    if args.fillets is not None and args.fillets < 1:
        raise RunRefused(f"--fillets must be >= 1, got {args.fillets}")
    if args.duration is not None and not 0.0 < args.duration <= MAX_SPAWN_DURATION_S:
        raise RunRefused(f"--duration must be in (0, {MAX_SPAWN_DURATION_S:g}] sim seconds, got {args.duration:g}")
    if not 0.0 <= args.side_rate <= MAX_SIDE_RATE_HZ:
        raise RunRefused(f"--side-rate must be in [0, {MAX_SIDE_RATE_HZ:g}] Hz (0: no side camera), "
                         f"got {args.side_rate:g}")
    if not all(0 <= k < math.inf for k in args.k):
        raise RunRefused(f"--k values must be finite and >= 0, got {' '.join(f'{k:g}' for k in args.k)}")
    if args.namespace and not re.fullmatch(r"/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*", args.namespace):
        raise RunRefused(f"--namespace must be a ROS name like /line2, got '{args.namespace}'")


def run(args: argparse.Namespace) -> int:
    try:
        _validate(args)
        return line_run.run_checked(args)
    except RunRefused as exc:
        print(f"woody run: {exc}", file=sys.stderr)
        return 2
