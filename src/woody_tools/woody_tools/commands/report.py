"""`woody report BAG_OR_CSV`: rebuild report.md and its plots from a bag or a verdict table.

The report goes to a folder of its own (``--out``, by default ``<source folder>/<source name>-report/``), never
to the source's folder: there sit the run's own verdicts.csv and report.md, which a report of a bag cut short
would replace with fewer rows.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from woody_experiments.fillet_pictures import write_fillet_pictures
from woody_experiments.messages import rows_from_bag, settings_from_bag
from woody_experiments.run_report import build_report, read_csv, write_csv


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("source", help="an MCAP bag written by `woody run` / `recorder`, or a verdicts.csv")
    parser.add_argument("--out", default=None,
                        help="folder for report.md, plots and (from a bag) verdicts.csv; not the source's folder "
                             "(default: <source folder>/<source name>-report/)")
    parser.add_argument("--woody-k", type=float, default=50.0,
                        help="fillets with k at or above this are woody in the ground truth (default 50)")


def output_folder(source: Path, out: str | None) -> Path:
    """Where the report goes; ValueError (one line) when that is the source's folder, whose files it would
    overwrite."""
    folder = Path(out) if out else source.parent / f"{source.stem}-report"
    if folder.resolve() == source.parent.resolve():
        raise ValueError(f"--out {folder} is the folder of {source.name}: the report would overwrite the run's "
                         "own files there; choose another folder")
    return folder


def run(args: argparse.Namespace) -> int:
    source = Path(args.source)
    if not source.exists():
        print(f"woody report: {source}: no such file", file=sys.stderr)
        return 2
    ended, settings, pictures = None, None, []
    try:
        out = output_folder(source, args.out)
        if source.suffix == ".csv":
            rows = read_csv(source)
        else:
            rows, ended = rows_from_bag(source, args.woody_k)
            settings = settings_from_bag(source, rows)
            write_csv(rows, out / "verdicts.csv")
            if not ended:
                pictures = write_fillet_pictures(source, out)
        notes = [f"the bag ends early: {ended}; this report covers its readable part"] if ended else []
        report = build_report(rows, out, title=f"woody report of {source.name}", run_info=settings, notes=notes,
                              extra=pictures)
    except OSError as exc:
        print(f"woody report: {exc.filename or args.out}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    except Exception as exc:  # one clear line for any unreadable input
        print(f"woody report: {exc}", file=sys.stderr)
        return 2
    if ended:
        print(f"woody report: {ended}; reporting its readable part", file=sys.stderr)
    print(f"report: {report}")
    return 0
