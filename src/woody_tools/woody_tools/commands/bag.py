"""`woody bag info BAG` and `woody bag recover IN OUT`: inspect a bag, rescue a recording cut short."""

from __future__ import annotations

import argparse
import sys

from woody_bag.errors import BagError
from woody_bag.recovery import recover_bag
from woody_bag.summary import bag_summary, recording_text


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="bag_command", required=True, metavar="ACTION")
    info = sub.add_parser("info", help="topics, types, counts, duration and metadata of a bag (truncated too)")
    info.add_argument("bag", metavar="BAG", help="the .mcap file (or a directory holding one)")
    recover = sub.add_parser("recover", help="rewrite every complete chunk of a cut-short bag into a valid one")
    recover.add_argument("source", metavar="IN", help="the damaged .mcap (e.g. of a recorder killed with SIGKILL)")
    recover.add_argument("target", metavar="OUT", help="the .mcap to write (refused if it exists, unless --force)")
    recover.add_argument("--force", action="store_true", help="overwrite OUT")


def info_lines(summary: dict) -> list[str]:
    """The lines `woody bag info` prints for a `bag_summary`."""
    state = "complete" if summary["complete"] else "NOT FINALISED (no summary; read as a stream)"
    lines = [f"bag: {summary['path']} ({state})",
             f"recorded: {summary['duration_s']:.3f} s, {recording_text(summary)}"]
    if summary["error"]:
        lines.append(f"ends: {summary['error']}; `woody bag recover` rewrites the readable part")
    width = max((len(t) for t in summary["topics"]), default=0)
    for topic, topic_info in sorted(summary["topics"].items()):
        lines.append(f"  {topic:<{width}}  {topic_info['count']:>7}  {topic_info['type']}")
    for name, record in sorted(summary["metadata"].items()):
        lines.append(f"metadata {name}: " + ", ".join(f"{k}={v}" for k, v in sorted(record.items())))
    return lines


def run(args: argparse.Namespace) -> int:
    try:
        if args.bag_command == "info":
            print("\n".join(info_lines(bag_summary(args.bag))))
            return 0
        result = recover_bag(args.source, args.target, overwrite=args.force)
    except BagError as exc:
        print(f"woody bag: {exc}", file=sys.stderr)
        return 2
    ended = result["error"] or f"{args.source}: complete"
    print(f"recovered {result['messages']} messages on {len(result['topics'])} topics into {args.target} "
          f"(source ended: {ended})")
    return 0
