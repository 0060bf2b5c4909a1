"""Argument types the woody commands share, so a bad value stops a command with one line before it starts."""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable
from pathlib import Path

from woody_common.line import MAX_SPAWN_DURATION_S, SPEED_RANGE_FPM
from woody_experiments.conditions import SWEEP_CONDITIONS
from woody_sim.camera_description import is_camera_file
from woody_sim.line_geometry import TOP_CAMERA_PRESETS, top_camera_preset
from woody_sim.meshes import MAX_YAW_SD_DEG


def number(check: Callable[[float], bool], requirement: str) -> Callable[[str], float]:
    """An argparse type: one number passing ``check``; ``requirement`` says what the check asks."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not check(value):
            raise argparse.ArgumentTypeError(f"{requirement}, got {text}")
        return value
    return parse


def number_list(check: Callable[[float], bool], requirement: str) -> Callable[[str], list[float]]:
    """An argparse type: comma-separated numbers, every one passing ``check``."""
    one = number(check, requirement)

    def parse(text: str) -> list[float]:
        items = [item.strip() for item in text.split(",") if item.strip()]
        if not items:
            raise argparse.ArgumentTypeError("expected at least one number")
        return [one(item) for item in items]
    return parse


def _positive(value: float) -> bool:
    return math.isfinite(value) and value > 0.0


POSITIVE_NUMBER = number(_positive, "must be a positive number")
POSITIVE_NUMBERS = number_list(_positive, "every value must be a positive number")
STIFFNESSES = number_list(lambda k: math.isfinite(k) and k >= 0.0, "every k must be a finite number >= 0")
LINE_SPEEDS = number_list(lambda s: SPEED_RANGE_FPM[0] <= s <= SPEED_RANGE_FPM[1],
                          f"every speed must be within {SPEED_RANGE_FPM[0]:g}..{SPEED_RANGE_FPM[1]:g} FPM")
def _conditions(text: str) -> list[str]:
    """Comma-separated sweep condition names, each known (woody_experiments.conditions)."""
    names = [item.strip() for item in text.split(",") if item.strip()]
    unknown = [n for n in names if n not in SWEEP_CONDITIONS]
    if not names or unknown:
        raise argparse.ArgumentTypeError(f"expected conditions among {', '.join(SWEEP_CONDITIONS)}, got {text!r}")
    return list(dict.fromkeys(names))


CONDITIONS = _conditions
YAW_SPREAD = number(lambda deg: 0.0 <= deg <= MAX_YAW_SD_DEG, f"must be within 0..{MAX_YAW_SD_DEG:g} degrees")


def add_yaw_sd(parser: argparse.ArgumentParser, scope: str) -> None:
    """``--yaw-sd DEG`` (woody_sim.meshes.mesh_yaw); ``scope`` ends the help with where the setting applies."""
    parser.add_argument("--yaw-sd", type=YAW_SPREAD, default=0.0, metavar="DEG",
                        help="fillets lie turned on the belt: each mesh by DEG x a normal draw seeded by its name, "
                             f"the same at every k and speed (default 0: straight; {scope})")


def add_top_camera(parser: argparse.ArgumentParser, scope: str) -> None:
    """``--top-camera PRESET|FILE`` of the headless commands; ``scope`` ends the help with where it applies."""
    parser.add_argument("--top-camera", default="default", metavar="PRESET|FILE",
                        help=f"top camera: a preset ({', '.join(sorted(TOP_CAMERA_PRESETS))}; default: 672x376, "
                             "0.75 m; paper: the seed system's 960x696, 86.6 deg, 0.33 m) or a camera description "
                             f"file (config/cameras/*.yaml); {scope}")


def top_camera_problem(args: argparse.Namespace) -> str:
    """What is wrong with ``args.top_camera`` ('' when nothing); a camera file is made absolute, since the
    workers read the same file."""
    try:
        top_camera_preset(args.top_camera)
    except ValueError as exc:
        return f"--top-camera: {exc}"
    if is_camera_file(args.top_camera):
        args.top_camera = str(Path(args.top_camera).resolve())
    return ""


def add_physics_workers(parser: argparse.ArgumentParser | argparse._ArgumentGroup, scope: str) -> None:
    """``--physics-workers N`` (line_sim's ``physics_workers``); ``scope`` starts the help with what it applies to."""
    parser.add_argument("--physics-workers", type=int, default=None, metavar="N",
                        help=f"{scope}worker processes sharing the physics with line_sim (0: all in line_sim; at most "
                             "the core count; default line_sim's, 1)")


def speed_change(text: str) -> tuple[float, float]:
    """``FPM@SECONDS`` (a belt speed change during a run) as (FPM, sim s); a ValueError says what is expected."""
    low, high = SPEED_RANGE_FPM
    try:
        fpm, at = (float(part) for part in text.split("@"))
    except ValueError:
        fpm = at = math.nan
    if not (low <= fpm <= high and 0.0 <= at <= MAX_SPAWN_DURATION_S):
        raise ValueError(f"expected FPM@SECONDS with FPM in [{low:g}, {high:g}] and SECONDS in "
                         f"[0, {MAX_SPAWN_DURATION_S:g}], got '{text}'")
    return fpm, at


def _speed_change_type(text: str) -> tuple[float, float]:
    try:
        return speed_change(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


SPEED_CHANGE = _speed_change_type
"""An argparse type for ``--speed-change FPM@SECONDS``."""


def out_folder_problem(out: Path) -> str | None:
    """Why ``out`` cannot become a folder (a file in its place or on its path, a folder it may not write in),
    else None; nothing is created, so a command can refuse before it starts its work."""
    for path in (out, *out.parents):
        if path.exists():
            if not path.is_dir():
                return f"{path} is not a folder"
            return None if os.access(path, os.W_OK) else f"{path} is not writable"
    return None
