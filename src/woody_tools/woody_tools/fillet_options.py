"""Command-line options shared by the commands that lay fillets on a belt: woody sweep, run and calibrate."""

from __future__ import annotations

import argparse

from woody_sim.meshes import MAX_YAW_SD_DEG


def yaw_spread(text: str) -> float:
    """``--yaw-sd``'s value, checked here so a bad one stops the command with one line instead of failing every run."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected degrees, got {text!r}") from None
    if not 0.0 <= value <= MAX_YAW_SD_DEG:
        raise argparse.ArgumentTypeError(f"must be within 0..{MAX_YAW_SD_DEG:g} degrees, got {text}")
    return value


def add_yaw_sd(parser: argparse.ArgumentParser, scope: str) -> None:
    """``--yaw-sd DEG`` (woody_sim.meshes.mesh_yaw); ``scope`` ends the help with where the setting applies."""
    parser.add_argument("--yaw-sd", type=yaw_spread, default=0.0, metavar="DEG",
                        help="fillets lie turned on the belt: each mesh by DEG x a normal draw seeded by its name, "
                             f"the same at every k and speed (default 0: straight; {scope})")
