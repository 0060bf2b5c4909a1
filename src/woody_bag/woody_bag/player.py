"""The player `woody replay` drives: a bag's serialized messages republished with their recorded timing.

The options and exit codes are `woody_tools.commands.replay`'s. Behaviour:

- Messages are published as the recorded CDR bytes (no decode), each on a
  publisher of its recorded type, with the QoS its recorded publishers offered
  (reliable unless they were all best-effort; transient-local when they all
  were, e.g. ``/line/ground_truth``), keep-last 100.
- Pacing: message *i* goes out at ``start + (log_time_i - log_time_0) / rate``
  on the wall clock (``log_time`` = the recorder's clock at reception: the line's sim time in a
  ``woody run`` bag, so a bag plays at the line's own pace).
  A replayer that falls behind publishes at once and never skips.
- ``/clock``: the recorded ``/clock`` messages are republished unchanged in
  their place, so ``use_sim_time`` nodes see the sim times of the recording
  (running ``rate`` times as fast). A bag without ``/clock`` gets one
  synthesised from the log times (``--clock-rate`` Hz, plus once before every
  message). ``--no-clock`` publishes none. ``--topics`` selects data topics
  only; ``/clock`` follows ``--no-clock``.
- Before playing it waits up to ``--wait-for-subscribers`` seconds until every
  publisher has a subscriber, then ``--start-delay`` seconds more.
- ``--loop`` starts over after the last message (sim time then jumps back).
- Into a running graph: topics that live nodes already publish (found in the
  first ``--discovery`` seconds) are skipped with one warning line, so the
  graph's outputs are not doubled (``--keep-live`` plays them anyway). The
  player keeps looking every ``LIVE_CHECK_S`` while it waits for subscribers
  and during playback (endpoint discovery can take seconds): when a live node
  starts publishing a topic it replays (a grader started after the replay),
  it stops replaying that topic, /clock included, with one line.
  ``--exclude`` drops topics by name; ``--namespace NS`` plays under NS.
"""

from __future__ import annotations

import argparse
import re
import sys
import threading
import time

from woody_bag.errors import BagError
from woody_bag.qos import parse_qos_profiles
from woody_bag.reader import read_bag
from woody_bag.schemas import message_class, message_definition
from woody_common.ros_params import stop_handler
from woody_common.stamps import nanoseconds_to_stamp

CLOCK = "/clock"
UNNAMED = "_NODE_NAME_UNKNOWN_"
"""The node name of a publisher discovered before its node's name (shown as "?")."""
LIVE_CHECK_S = 0.1
"""How often playback looks for live publishers of the topics it replays (s of wall time)."""


class Stop:
    """Set by SIGINT/SIGTERM (when run in the main thread) or `request`."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self.request = stop_handler(self.event)
        """Sets the event once (a signal handler: a second signal never waits on the event's lock)."""

    def __bool__(self) -> bool:
        return self.event.is_set()


def qos_for(qos_yaml: str):
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    profiles = parse_qos_profiles(qos_yaml)
    best_effort = bool(profiles) and all(p.get("reliability") == "best_effort" for p in profiles)
    latched = bool(profiles) and all(p.get("durability") == "transient_local" for p in profiles)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                      reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def outdated(topic_info: dict) -> bool:
    """A woody_msgs topic whose recorded fields differ from the current ones cannot be decoded by them (a comment
    or spacing changed since the recording does not matter)."""
    type_name = topic_info["type"]
    if not type_name.startswith("woody_msgs/") or not topic_info.get("definition"):
        return False
    return definition_fields(topic_info["definition"]) != definition_fields(message_definition(type_name))


def definition_fields(definition: str) -> list[str]:
    """The lines of a ``ros2msg`` definition that make the type (fields, constants, the nested types' headers),
    without comments, blank lines and spacing (``X = 1`` is ``X=1``); a ``#`` inside a quoted constant is kept."""
    lines = []
    for line in definition.splitlines():
        quote = None
        for i, char in enumerate(line):
            if char in "\"'" and quote in (None, char):
                quote = None if quote else char
            elif char == "#" and quote is None:
                line = line[:i]
                break
        if line.strip():
            lines.append(re.sub(r" ?= ?", "=", " ".join(line.split())))
    return lines


def playable_types(args: argparse.Namespace, path, in_bag: dict[str, dict]) -> tuple[dict[str, type], list[str]]:
    """Topic -> message class of the selected topics this workspace can publish, and why each other one is skipped
    (``skipping /topic: ...``); ValueError when the bag holds none of the requested topics."""
    requested = None if not args.topics else [t if t.startswith("/") else "/" + t for t in args.topics]
    skipped = []
    if requested is not None:
        missing = [t for t in requested if t not in in_bag]
        if len(missing) == len(requested):
            raise ValueError(f"{path}: holds none of {' '.join(requested)} (it has {' '.join(sorted(in_bag))})")
        if missing:
            skipped.append(f"{path}: not in the bag, skipped: {' '.join(missing)}")
    excluded = {t if t.startswith("/") else "/" + t for t in args.exclude}
    selected = [t for t in (requested or sorted(in_bag)) if t in in_bag and t != CLOCK and t not in excluded]
    types: dict[str, type] = {}
    for topic in selected:
        try:
            types[topic] = message_class(in_bag[topic]["type"])
        except LookupError as exc:
            skipped.append(f"skipping {topic}: {exc}")
            continue
        if outdated(in_bag[topic]):
            del types[topic]
            skipped.append(f"skipping {topic}: recorded with an older {in_bag[topic]['type']} definition than this "
                           "workspace's woody_msgs (replay the camera topics into the vision nodes instead)")
    return types, skipped


def live_publishers(node, topics, namespace: str) -> dict[str, list[str]]:
    """{topic: names of the other nodes publishing it} for the recorded ``topics`` that live nodes publish."""
    own = (node.get_name(), node.get_namespace())
    live = {}
    for topic in topics:
        nodes = sorted({i.node_name.replace(UNNAMED, "?") for i in node.get_publishers_info_by_topic(
            moved(topic, namespace)) if (i.node_name, i.node_namespace) != own})
        if nodes:
            live[topic] = nodes
    return live


def live_text(live: dict[str, list[str]]) -> str:
    return ", ".join(f"{t} (by {' '.join(n)})" for t, n in live.items())


def skip_live(node, args, types: dict[str, type], clock_mode: str | None, stop: Stop) -> str | None:
    """Drop from ``types`` the topics live nodes already publish; the clock mode left (None if /clock is live).

    Replaying a bag's tracks or verdicts into a running graph would double its
    outputs (and a second /clock would fight the live one), so those topics are
    skipped with one warning line naming the nodes; ``--keep-live`` plays them anyway.
    The player keeps looking during playback (`Player`): a node that comes up later stops its topics there.
    """
    _discover(node, args.discovery, stop)
    live = live_publishers(node, [*types, *([CLOCK] if clock_mode else [])], args.namespace)
    for topic in live:
        types.pop(topic, None)
    if live:
        print("replay: not replaying topics live nodes publish (--keep-live plays them anyway): " + live_text(live),
              file=sys.stderr, flush=True)
    return None if CLOCK in live else clock_mode


def _discover(node, limit: float, stop: Stop, settle: float = 0.5) -> None:
    """Wait until other nodes have been seen, each with its publishers, and none of that has changed for ``settle``
    s (or ``limit``): a node is known before its publishers are, and its publishers one by one."""
    deadline = time.monotonic() + limit
    seen: frozenset = frozenset()
    changed = time.monotonic()
    while not stop and time.monotonic() < deadline:
        graph = frozenset(_publishers_by_node(node))
        if graph != seen:
            seen, changed = graph, time.monotonic()
        elif graph and all(topics for _, topics in graph) and time.monotonic() - changed >= settle:
            return
        stop.event.wait(0.1)


def _publishers_by_node(node):
    """((node, namespace), frozenset of its published topics) of every other node in the graph."""
    from rclpy._rclpy_pybind11 import NodeNameNonExistentError

    for name, namespace in node.get_node_names_and_namespaces():
        if (name, namespace) == (node.get_name(), node.get_namespace()):
            continue
        try:
            topics = node.get_publisher_names_and_types_by_node(name, namespace)
        except NodeNameNonExistentError:  # it left between the two calls
            topics = []
        yield (name, namespace), frozenset(t for t, _ in topics)


def moved(topic: str, namespace: str) -> str:
    """A recorded (absolute) topic name moved under ``namespace`` ("" = unchanged)."""
    ns = namespace.strip("/")
    return f"/{ns}{topic}" if ns else topic


class Player:
    def __init__(self, node, args, path: str, info: dict, types: dict[str, type], clock_mode: str | None,
                 stop: Stop) -> None:
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from rosgraph_msgs.msg import Clock

        self.node, self.args, self.path, self.info, self.stop = node, args, path, info, stop
        self.clock_mode = clock_mode
        self.publishers = {topic: node.create_publisher(cls, moved(topic, args.namespace),
                                                        qos_for(info["topics"][topic]["qos"]))
                           for topic, cls in types.items()}
        self.clock_publisher = None
        if clock_mode is not None:
            self.clock_publisher = node.create_publisher(
                Clock, moved(CLOCK, args.namespace), QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        self._clock_msg = Clock()
        self._last_clock = -1
        self.topics = list(types) + ([CLOCK] if clock_mode == "recorded" else [])
        self.count = 0
        self.bag_seconds = 0.0
        self._next_live_check = 0.0

    def say(self, text: str) -> None:
        if not self.args.quiet:
            print(f"replay: {text}", flush=True)

    # ------------------------------------------------------------------ waiting
    def _sleep(self, seconds: float) -> None:
        self.stop.event.wait(max(0.0, seconds))

    def _wait_for_subscribers(self) -> None:
        limit = self.args.wait_for_subscribers
        if limit <= 0 or not self.publishers:
            return
        deadline = time.monotonic() + limit
        while not self.stop and time.monotonic() < deadline:
            self._check_live(0.0)  # discovery goes on while we wait
            if all(p.get_subscription_count() > 0 for p in self.publishers.values()):
                self._sleep(0.2)  # let the subscribers' side of the match settle too
                return
            self._sleep(0.02)
        lonely = [t for t, p in self.publishers.items() if p.get_subscription_count() == 0]
        if lonely and not self.stop:
            self.say(f"no subscriber after {limit:g} s on {' '.join(lonely)}; playing anyway")

    def _publish_clock(self, bag_ns: int) -> None:
        if bag_ns <= self._last_clock or self.clock_publisher is None:
            return
        self._last_clock = bag_ns
        self._clock_msg.clock = nanoseconds_to_stamp(bag_ns)
        self.clock_publisher.publish(self._clock_msg)

    def _check_live(self, bag_s: float) -> None:
        """Stop replaying the topics a live node has started to publish (checked every `LIVE_CHECK_S`), with one
        line: replaying beside a live grader would double its verdicts."""
        if self.args.keep_live or time.monotonic() < self._next_live_check:
            return
        self._next_live_check = time.monotonic() + LIVE_CHECK_S
        replayed = [*self.publishers, *([CLOCK] if self.clock_publisher is not None else [])]
        live = live_publishers(self.node, replayed, self.args.namespace)
        if not live:
            return
        for topic in live:
            if topic == CLOCK:
                self.node.destroy_publisher(self.clock_publisher)
                self.clock_publisher, self.clock_mode = None, None
            else:
                self.node.destroy_publisher(self.publishers.pop(topic))
        print(f"replay: live nodes publish {live_text(live)}: not replayed from t={bag_s:.3f}s of the bag on",
              file=sys.stderr, flush=True)

    def _wait_until(self, target: float, t0_wall: float, t0_bag: int, next_bag: int) -> None:
        synth = self.clock_mode == "synthesised"
        period = 1.0 / self.args.clock_rate
        while not self.stop:
            now = time.monotonic()
            self._check_live((now - t0_wall) * self.args.rate)
            if synth:
                self._publish_clock(min(next_bag, t0_bag + int((now - t0_wall) * self.args.rate * 1e9)))
            remaining = target - now
            if remaining <= 0:
                return
            self._sleep(min(remaining, period if synth else 0.05))

    # ------------------------------------------------------------------ playing
    def play(self) -> int:
        readable = "" if self.info["complete"] else " readable (no summary: the recording was cut short)"
        self.say(f"{self.path}: {len(self.publishers)} topics, {self.info['message_count']} messages{readable}, "
                 f"{self.info['duration_s']:.1f} s at rate {self.args.rate:g}, clock {self.clock_mode or 'off'}")
        self._wait_for_subscribers()
        self._sleep(self.args.start_delay)
        started = time.monotonic()
        warned = False
        passes = 0
        while not self.stop:
            played, error = self._play_once()
            passes += 1
            if error and not warned:
                print(f"replay: {error}; stopped there", file=sys.stderr, flush=True)
                warned = True
            if not self.args.loop or played == 0:
                break
        self._wait_for_delivery()
        self.say(f"{'stopped' if self.stop else 'done'}: {self.count} messages"
                 f"{f' in {passes} passes' if passes > 1 else ''}, {time.monotonic() - started:.1f} s")
        return 0

    def _wait_for_delivery(self) -> None:
        """Let reliable subscribers acknowledge the last messages, /clock included, before the process exits."""
        from rclpy.duration import Duration

        publishers = [*self.publishers.values(), *([self.clock_publisher] if self.clock_publisher else [])]
        for publisher in publishers:
            publisher.wait_for_all_acked(Duration(seconds=1.0))

    def _play_once(self) -> tuple[int, str | None]:
        t0_bag = t0_wall = None
        played = 0
        progress = self.args.progress if not self.args.quiet else 0
        next_progress = time.monotonic() + progress if progress > 0 else float("inf")
        total = self.info["duration_s"]
        try:
            for topic, _type, data, log_time in read_bag(self.path, topics=self.topics):
                if t0_bag is None:
                    t0_bag, t0_wall = log_time, time.monotonic()
                target = t0_wall + (log_time - t0_bag) / 1e9 / self.args.rate
                self._wait_until(target, t0_wall, t0_bag, log_time)
                if self.stop:
                    break
                publisher = self.clock_publisher if topic == CLOCK else self.publishers.get(topic)
                if publisher is None:
                    continue  # a live node publishes it now
                if topic != CLOCK and self.clock_mode == "synthesised":
                    self._publish_clock(log_time)
                publisher.publish(data)
                played += 1
                self.count += 1
                if time.monotonic() >= next_progress:
                    next_progress += progress
                    self.say(f"{(log_time - t0_bag) / 1e9:.1f} / {total:.1f} s, {self.count} messages")
        except BagError as exc:
            return played, str(exc)
        finally:
            self._last_clock = -1  # a new pass may start sim time over
        return played, None
