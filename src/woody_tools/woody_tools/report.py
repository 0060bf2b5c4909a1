"""`woody report BAG_OR_CSV`: rebuild report.md and its plots from a bag or a verdict table."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from woody_common import topics
from woody_tools.run_report import build_report, join, read_csv, write_csv


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("source", help="an MCAP bag written by `woody run` / `recorder`, or a verdicts.csv")
    parser.add_argument("--out", default=None, help="folder for report.md and plots (default: beside the source)")
    parser.add_argument("--woody-k", type=float, default=50.0,
                        help="fillets with k at or above this are woody in the ground truth (default 50)")


def rows_from_bag(path: Path, woody_k: float = 50.0) -> tuple[list[dict], str | None]:
    """Ground truth and verdicts recorded in a bag (of a line in any namespace), joined into verdict-table rows,
    and where a truncated bag ends (None for a complete one): the readable part of a cut recording still counts."""
    from woody_tools.line_run import spawn_from_msg, verdict_from_msg
    from woody_tools.mcap_io import BagError, bag_topics, decode, read_bag

    spawns, verdicts, ended = [], [], None
    try:
        wanted = [t for t in bag_topics(path) if t.endswith(("/" + topics.GROUND_TRUTH, "/" + topics.VERDICTS))]
        for topic, type_name, data, _log_time in read_bag(path, topics=wanted):
            msg = decode(type_name, data)
            if topic.endswith("/" + topics.GROUND_TRUTH):
                spawns.append(spawn_from_msg(msg))
            else:
                verdicts.append(verdict_from_msg(msg))
    except BagError as exc:
        if not spawns and not verdicts:
            raise
        ended = str(exc)
    if not spawns and not verdicts:
        raise ValueError(f"{path}: no /line/ground_truth or /grading/verdicts messages in this bag")
    return join(spawns, verdicts, woody_k), ended


def settings_from_bag(path: Path, rows: list[dict]) -> dict | None:
    """The settings table of the run that recorded the bag (the recorder's ``woody.run`` record)."""
    from woody_tools.mcap_io import bag_metadata

    record = bag_metadata(path).get("woody", {}).get("run_settings")
    if not record:
        return None
    settings = json.loads(record)
    settings["fillets spawned"] = sum(1 for r in rows if r.get("truth"))
    settings["verdicts"] = sum(1 for r in rows if r["verdict"] != "missing")
    return settings


def run(args: argparse.Namespace) -> int:
    source = Path(args.source)
    if not source.exists():
        print(f"woody report: {source}: no such file", file=sys.stderr)
        return 2
    out = Path(args.out) if args.out else source.parent
    ended, settings = None, None
    try:
        if source.suffix == ".csv":
            rows = read_csv(source)
        else:
            rows, ended = rows_from_bag(source, args.woody_k)
            settings = settings_from_bag(source, rows)
            write_csv(rows, out / "verdicts.csv")
        notes = [f"the bag ends early: {ended}; this report covers its readable part"] if ended else []
        report = build_report(rows, out, title=f"woody report of {source.name}", run_info=settings, notes=notes)
    except OSError as exc:
        print(f"woody report: {exc.filename or out}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    except Exception as exc:  # one clear line for any unreadable input
        print(f"woody report: {exc}", file=sys.stderr)
        return 2
    if ended:
        print(f"woody report: {ended}; reporting its readable part", file=sys.stderr)
    print(f"report: {report}")
    return 0
