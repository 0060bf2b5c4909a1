"""The `woody` command: one entry point with subcommands, in the spirit of the `ros2` CLI."""

from __future__ import annotations

import argparse
import importlib
import sys

SUBCOMMANDS = [
    ("run", "run", "run a multi-lane line: sim + vision + gate + recorder; bag, verdicts.csv, report.md"),
    ("replay", "replay", "republish a recorded bag with its original timing and /clock"),
    ("report", "report", "rebuild report.md and plots from a bag or a verdicts.csv"),
    ("bag", "bag", "`woody bag info BAG`, `woody bag recover IN OUT` (rescue a recording cut short)"),
    ("bench", "bench", "benchmarks: `woody bench sim`, `woody bench vision`, `woody bench graph`"),
    ("sweep", "sweep", "the paper's drop-test grid (meshes x k x speed), parallel and resumable; runs.csv, results.md"),
    ("evaluate", "evaluate", "the live line over a grid of seeds x conditions x lanes x speeds, one woody run each, "
                             "resumable; evaluation.md, evaluation.csv"),
    ("dataset", "dataset", "labelled frames of a grid of runs: COCO instance masks, per-fillet sequences, splits by "
                           "mesh; resumable"),
    ("meshes", "meshes",
     "mesh sets: `woody meshes stats SPEC...` prints shape descriptors per mesh and per set"),
    ("calibrate", "calibrate", "fit M, c and the drive friction to the paper's side view, choose the Φ threshold; "
                               "writes config/calibration.yaml"),
    ("soak", "soak", "physics soak: N fillet passages over the roller across k, mass, speed and lanes; blow-ups"),
    ("camera", "camera", "`woody camera setup BAG --out PARAMS.yaml`: the camera's mount, the flow, roller edge and "
                         "lanes from a recording; the vision's parameters"),
]
"""(subcommand, module in woody_tools.commands with add_arguments(parser) and run(args) -> int, help)."""


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser; with ``only``, just that subcommand's module is imported (pybullet stays unloaded for `report`)."""
    parser = argparse.ArgumentParser(prog="woody",
                                     description="Woody-breast grading line: run, record, replay, report.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, module_name, help_text in SUBCOMMANDS:
        command = sub.add_parser(name, help=help_text)
        if only is None or only == name:
            module = importlib.import_module(f"woody_tools.commands.{module_name}")
            module.add_arguments(command)
            command.set_defaults(func=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    only = argv[0] if argv and argv[0] in {name for name, _, _ in SUBCOMMANDS} else None
    if only == "run":  # a run owns processes: a stop signal is kept from the first instant, before slow imports
        from woody_tools.processes import STOP

        STOP.install()
    args = build_parser(only).parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("woody: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
