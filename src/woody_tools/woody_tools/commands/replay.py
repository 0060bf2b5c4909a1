"""``woody replay BAG``: republish a bag's serialized messages with their recorded timing (`woody_bag.player`).

`add_arguments` and `run` are the subcommand's whole interface (the ``woody`` CLI
calls them). What is published, when, with which QoS and clock, and which topics
are skipped in a running graph is the player's behaviour (:mod:`woody_bag.player`).

Exit codes: 0 when the bag (or its readable part) was played or the replay was
stopped by SIGINT/SIGTERM; 2 with one line on stderr, no traceback, when the
bag is missing, not an MCAP, holds none of the requested topics or nothing
playable, or an argument is invalid; 1 for a failure of ROS itself. A
truncated bag (a killed recorder) or one with a damaged chunk (CRC mismatch)
plays up to where it is readable, then one line on stderr says where it
stopped (``replay: <bag>: truncated after N messages at t=12.345s; stopped
there``), and the exit code is still 0: the data that exists was replayed
completely. With ``--loop`` the readable part loops and the line is printed once.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading

from woody_bag.errors import BagError
from woody_bag.player import CLOCK, Player, Stop, playable_types, skip_live
from woody_bag.summary import bag_summary


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", metavar="BAG", help="the .mcap file (or a directory holding one)")
    parser.add_argument("--rate", type=float, default=1.0, help="speed factor (2 = twice as fast); default 1")
    parser.add_argument("--loop", action="store_true", help="start over after the last message")
    parser.add_argument("--topics", nargs="+", metavar="TOPIC", help="replay only these topics (default: all)")
    parser.add_argument("--no-clock", action="store_true", help="publish no /clock (neither recorded nor synthesised)")
    parser.add_argument("--start-delay", type=float, default=0.0, metavar="S",
                        help="seconds to wait after the publishers are up, before the first message")
    parser.add_argument("--wait-for-subscribers", type=float, default=2.0, metavar="S",
                        help="wait up to S seconds for every topic to have a subscriber (0 = don't); default 2")
    parser.add_argument("--clock-rate", type=float, default=100.0, metavar="HZ",
                        help="rate of the /clock synthesised for bags without one; default 100")
    parser.add_argument("--progress", type=float, default=5.0, metavar="S",
                        help="print progress every S seconds (0 = never); default 5")
    parser.add_argument("--quiet", action="store_true", help="print only warnings and errors")
    parser.add_argument("--exclude", nargs="+", default=[], metavar="TOPIC", help="never replay these topics")
    parser.add_argument("--keep-live", action="store_true",
                        help="also replay topics that live nodes already publish (default: skip them, with a warning)")
    parser.add_argument("--discovery", type=float, default=3.0, metavar="S",
                        help="look for live publishers of the bag's topics for up to S seconds (less once the graph "
                             "is seen and settled); default 3")
    parser.add_argument("--namespace", default="", metavar="NS",
                        help="publish under NS: the bag's /a/b as NS/a/b and /clock as NS/clock, like the nodes of "
                             "`woody run --namespace NS`")


def _fail(message: str) -> int:
    print(f"replay: {message}", file=sys.stderr, flush=True)
    return 2


def run(args: argparse.Namespace) -> int:
    """Play the bag; see the module docstring for options and exit codes."""
    if not args.rate > 0:
        return _fail(f"--rate must be > 0 (got {args.rate})")
    if args.start_delay < 0 or args.wait_for_subscribers < 0 or args.discovery < 0 or args.clock_rate <= 0:
        return _fail("--start-delay, --wait-for-subscribers and --discovery must be >= 0, --clock-rate > 0")
    try:
        info = bag_summary(args.bag)
    except BagError as exc:
        return _fail(str(exc))
    path = info["path"]
    in_bag: dict[str, dict] = info["topics"]
    if not in_bag or not info["message_count"]:
        return _fail(info["error"] or f"{path}: the bag holds no messages")

    try:
        types, skipped = playable_types(args, path, in_bag)
    except ValueError as exc:
        return _fail(str(exc))
    clock_mode = None if args.no_clock else ("recorded" if CLOCK in in_bag else "synthesised")
    if not types and clock_mode != "recorded":
        why = f" ({'; '.join(skipped)})" if skipped else ""
        return _fail(f"{path}: nothing playable in the selected topics{why}")
    for line in skipped:
        print(f"replay: {line}", file=sys.stderr)

    try:
        import rclpy
        from rclpy.signals import SignalHandlerOptions
    except Exception as exc:  # noqa: BLE001
        print(f"replay: cannot import rclpy: {exc}", file=sys.stderr)
        return 1

    stop = Stop()
    previous = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, stop.request)
    context = rclpy.Context()
    try:
        rclpy.init(args=["woody_replay"], context=context, signal_handler_options=SignalHandlerOptions.NO)
        node = rclpy.create_node("woody_replay", context=context)
        try:
            if not args.keep_live:
                clock_mode = skip_live(node, args, types, clock_mode, stop)
            if not types and clock_mode is None:
                return _fail(f"{path}: nothing left to play (live nodes publish every selected topic)")
            player = Player(node, args, path, info, types, clock_mode, stop)
            return player.play()
        finally:
            node.destroy_node()
    except Exception as exc:  # noqa: BLE001 - one line, not a traceback
        print(f"replay: failed: {type(exc).__name__}: {exc}".replace("\n", " "), file=sys.stderr)
        return 1
    finally:
        rclpy.try_shutdown(context=context)
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def main(argv: list[str] | None = None) -> int:
    """Stand-alone entry (``python -m woody_tools.commands.replay BAG ...``)."""
    parser = argparse.ArgumentParser(prog="woody replay", description=__doc__.split("\n")[0])
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
