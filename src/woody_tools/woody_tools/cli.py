"""The `woody` command: one entry point with subcommands, in the spirit of the `ros2` CLI."""

from __future__ import annotations

import argparse
import sys


def _run(args: argparse.Namespace) -> int:
    from woody_tools import line_run

    return line_run.run(args)


def _replay(args: argparse.Namespace) -> int:
    from woody_tools import replay

    return replay.run(args)


def _report(args: argparse.Namespace) -> int:
    from woody_tools import report_command

    return report_command.run(args)


def _bench(args: argparse.Namespace) -> int:
    from woody_tools import bench

    return bench.run(args)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="woody", description="Woody-breast grading line: run, record, replay, report.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    from woody_tools import bench, line_run, replay, report_command

    run = sub.add_parser("run", help="run a multi-lane line: sim + vision + gate + recorder; bag, verdicts.csv, report.md")
    line_run.add_arguments(run)
    run.set_defaults(func=_run)

    rep = sub.add_parser("replay", help="republish a recorded bag with its original timing and /clock")
    replay.add_arguments(rep)
    rep.set_defaults(func=_replay)

    report = sub.add_parser("report", help="rebuild report.md and plots from a bag or a verdicts.csv")
    report_command.add_arguments(report)
    report.set_defaults(func=_report)

    b = sub.add_parser("bench", help="benchmarks: `woody bench sim` and `woody bench vision`")
    bench.add_arguments(b)
    b.set_defaults(func=_bench)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("woody: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
