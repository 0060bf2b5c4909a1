"""``recorder``: record topics of the running graph into one MCAP bag (see `woody_bag.writer`).

Parameters (``--ros-args -p name:=value``):

- ``output`` (string): path of the ``.mcap``; default ``bags/<YYYYmmdd-HHMMSS>.mcap``
  under the working directory. An existing file is never overwritten.
- ``topics`` (string array): topics to record; empty = every topic of the graph
  whose type is importable, except those matching ``exclude_regex``.
- ``topic_regex`` (string): also record topics matching this regular expression
  (with ``topics`` given: the union of both).
- ``exclude_regex`` (string): never record matching topics; default
  ``/rosout``, ``/parameter_events`` and hidden (``/_...``) topics.
- ``discovery_period`` (s, 0.5): how often the graph is searched for new topics
  during the whole run.
- ``queue_depth`` (1000): keep-last depth of the subscriptions (per topic): what the
  middleware holds for the recorder while its Python thread waits for a CPU (at 100,
  a 3-lane line beside two busy processes loses hundreds of messages).
- ``compression`` (``zstd``|``lz4``|``none``), ``compression_level`` (zstd
  level, 1), ``chunk_size`` (bytes, 4 MiB), ``flush_period`` (s, 1.0: the
  longest a message waits in memory before its chunk is written; what a
  SIGKILL can lose), ``max_buffer_mb`` (512: received but unwritten data; a
  message arriving while it is full is dropped and counted lost).
- ``run_settings`` (string): a JSON object of the recorded run's settings, kept in
  the bag's ``woody`` metadata record (`woody report BAG` rebuilds its table from it).

Unknown parameter names, malformed overrides and other arguments are refused
with one line (exit code 2); ``--help`` prints this list.

Timing: the MCAP ``log_time`` of a message is the **recorder's own clock at
reception**, as ``ros2 bag record`` writes it: the line's sim time when
``use_sim_time`` is true (``woody run`` sets it, like ``ros2 bag record
--use-sim-time``), else the system clock, ns. Messages are taken one callback at a
time on one thread and written in that order, so ``log_time`` never decreases and
a bag plays in Foxglove and `woody replay` at the line's own pace, whatever
the line's real-time factor was. ``publish_time`` is the publisher's source
timestamp (wall clock). Messages received before the first ``/clock`` (latched
topics) are stamped 0, as rosbag2 stamps them.

QoS: each topic is subscribed the way its publishers offer it (rosbag2's
adaptive rule): reliable unless some publisher is best-effort, transient-local
(latched, e.g. ``/line/ground_truth``, ``/tf_static``) when every publisher is,
keep-last ``queue_depth``. The offered profiles are stored in the channel's
``offered_qos_profiles`` metadata.

A subscription callback takes the subscription's whole backlog (one executor
round per burst, not per message) and only queues the serialized bytes; a
writer thread builds, compresses (zstd releases the GIL) and writes chunks, so
compression and disk I/O use the second core. SIGINT/SIGTERM finish the file
(summary and indexes) and log one line: messages, MB on disk (compressed), and per
topic written/published (``/?`` when several publishers share it), naming what was
lost (a gap in the publisher's sequence numbers, so a lost tail counts once a later
message of that publisher arrives: lost in transport, or dropped
because more than ``max_buffer_mb`` was unwritten; the callbacks never wait for
the writer, so the middleware never holds more than ``queue_depth`` per topic
for the recorder); the losses per topic
are also the bag's ``woody.losses`` metadata record (`woody_bag.summary.LOSSES_RECORD`),
which ``woody bag info``, ``woody run`` and its report.md show; exit code 0. A bad
parameter or an unwritable output: one error line, exit code 2.

Back-pressure: every 10 ms the newest ``/clock`` stamp written goes out on
``recorder/recorded_clock``; a line_sim told to wait for this recorder holds
its line while that lags (``max_lead_s``), so a line faster than the disk slows
down instead of losing messages.

A full disk or a file size limit (ENOSPC, EFBIG, handled alike; SIGXFSZ is
ignored) stops the recording: the file is cut back to its last whole record, one
error line (starting ``stopped recording:``) names the cause, the path and the
``woody bag recover`` command that writes a complete copy, exit code 1.
"""

from __future__ import annotations

import collections
import errno
import re
import signal
import struct
import sys
import threading
import time

import rclpy
from builtin_interfaces.msg import Time
from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.clock import Clock, ClockType
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
from rosgraph_msgs.msg import Clock as RosClock

from woody_bag.errors import BagError
from woody_bag.qos import qos_profiles_yaml, subscription_qos
from woody_bag.schemas import message_class, message_definition
from woody_bag.summary import LOSSES_RECORD, losses_record
from woody_bag.writer import BagWriter
from woody_common.diagnostics import ERROR, OK, WARN, DiagnosticsPublisher, Health
from woody_common.ros_params import check_overrides, declare, run_node, usage
from woody_common.topics import RECORDED_CLOCK

DEFAULT_EXCLUDE = r"^/(rosout|parameter_events)$|/_"
FAILURE_PREFIX = "stopped recording:"
"""Begins the recorder's one error line when the bag cannot be written (full disk, file size limit)."""


CLOCK_TYPE = "rosgraph_msgs/msg/Clock"
ANNOUNCE_PERIOD_S = 0.01
"""How often (wall s) the newest written /clock stamp goes out on ``recorder/recorded_clock``, when it moved."""


class ConfigError(ValueError):
    """A parameter the recorder cannot work with; the message is one line."""


class Recorder(Node):
    """Subscribes raw to the selected topics and writes them into one MCAP bag."""

    def __init__(self) -> None:
        super().__init__("recorder")
        given = self._declare()
        check_overrides(self)  # before the bag is opened; run_node turns the ValueError into one line
        output = given["output"] or f"bags/{time.strftime('%Y%m%d-%H%M%S')}.mcap"
        topics = self.get_parameter_or("topics", Parameter("topics", Parameter.Type.STRING_ARRAY, [])).value
        self._topics = {t if t.startswith("/") else "/" + t for t in (topics or []) if t}
        self._regex = self._compile("topic_regex", given["topic_regex"])
        self._exclude = self._compile("exclude_regex", given["exclude_regex"])
        self._depth = given["queue_depth"]
        self._flush_period = given["flush_period"]
        self._max_buffer = given["max_buffer_mb"] * 1024 * 1024
        run_info = {
            "recorder": "woody_bag.recorder_node", "topics": sorted(self._topics),
            "topic_regex": given["topic_regex"], "exclude_regex": given["exclude_regex"],
            "use_sim_time": bool(self.get_parameter("use_sim_time").value), "start_unix_ns": time.time_ns(),
            "log_time": "the recorder's clock at reception (sim time with use_sim_time), ns",
            "publish_time": "publisher's source timestamp (wall clock)",
            "run_settings": given["run_settings"],
        }
        try:
            self._writer = BagWriter(output, chunk_size=given["chunk_size"], compression=given["compression"],
                                     compression_level=given["compression_level"], metadata=run_info)
        except BagError as exc:
            raise ConfigError(str(exc)) from None
        self.output = self._writer.path

        self._cond = threading.Condition()
        self._items: collections.deque = collections.deque()
        self._buffered = 0
        self._stopping = False
        self._error: BaseException | None = None
        self._subscriptions_by_topic: dict[str, object] = {}
        self._offered: dict[str, int] = {}
        self._seen: dict[str, list] = {}  # topic -> [first publication seq, last, received, most publishers]
        self._dropped: dict[str, int] = {}  # topic -> messages dropped because the writer fell behind
        self._ignored: set[str] = set()
        self._clock_topics: set[str] = set()
        self._written_clock = self._announced_clock = None  # newest /clock written, and the one last published
        self._recorded_pub = self.create_publisher(RosClock, RECORDED_CLOCK, 10)
        self._start = time.monotonic()
        self._thread = threading.Thread(target=self._write_loop, name="mcap-writer", daemon=True)
        self._thread.start()
        self._discover()
        # Steady clock: with use_sim_time the graph's /clock may only start once we subscribe.
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(given["discovery_period"], self._discover, clock=steady)
        self.create_timer(ANNOUNCE_PERIOD_S, self._announce_written_clock, clock=steady)
        self.diagnostics = DiagnosticsPublisher(self, self.health)
        self.get_logger().info(
            f"recording to {self.output} ({'topics ' + ', '.join(sorted(self._topics)) if self._topics else ''}"
            f"{' regex ' + self._regex.pattern if self._regex else ''}"
            f"{'all topics' if not self._topics and not self._regex else ''}); log_time = "
            f"{'sim' if self.get_parameter('use_sim_time').value else 'system'} time at reception")

    def health(self) -> Health:
        """Messages lost (in transport, or dropped with the buffer full) are a warning; a write error an error."""
        drops = self.drops()
        lost = sum(max(0, p - w) for w, p in drops.values() if p is not None) + sum(self._dropped.values())
        values = {"messages written": sum(self._writer.counts.values()), "topics": len(drops),
                  "unwritten (MB)": self._buffered / 1e6, "lost": lost}
        if self._error is not None:
            return Health(ERROR, self._failure_line(), values)
        return Health(WARN if lost else OK, f"{values['messages written']} messages written, {lost} lost", values)

    # ------------------------------------------------------------------ parameters
    def _declare(self) -> dict:
        """Declare every parameter (numbers with their range, so NaN, infinity and values outside are refused with
        one line before the bag is opened); the values given, by name."""
        self.declare_parameter("topics", Parameter.Type.STRING_ARRAY, ParameterDescriptor(
            description="topics to record; empty = all importable topics", type=ParameterType.PARAMETER_STRING_ARRAY,
            read_only=True))
        return {
            "output": declare(self, "output", "", "path of the .mcap (default bags/<timestamp>.mcap)"),
            "topic_regex": declare(self, "topic_regex", "", "also record topics matching this regex"),
            "exclude_regex": declare(self, "exclude_regex", DEFAULT_EXCLUDE, "never record topics matching this"),
            "discovery_period": declare(self, "discovery_period", 0.5, "seconds between searches for new topics",
                                        0.01, 60.0),
            "queue_depth": declare(self, "queue_depth", 1000, "keep-last depth of each subscription", 1, 100_000),
            "compression": declare(self, "compression", "zstd", "chunk compression: zstd, lz4 or none"),
            "compression_level": declare(self, "compression_level", 1, "zstd level (1 keeps up with 200 Hz images)",
                                         1, 22),
            "chunk_size": declare(self, "chunk_size", 4 * 1024 * 1024, "bytes per MCAP chunk", 1, 1024 ** 3),
            "flush_period": declare(self, "flush_period", 1.0, "max seconds a message waits before its chunk is "
                                    "written (what a SIGKILL can lose)", 0.01, 60.0),
            "max_buffer_mb": declare(self, "max_buffer_mb", 512, "received but unwritten data held in memory",
                                     1, 65_536),
            "run_settings": declare(self, "run_settings", "", "JSON object of the recorded run's settings, kept in the "
                                    "bag's woody metadata record (woody report rebuilds its settings table from it)"),
        }

    def _compile(self, name: str, pattern: str) -> re.Pattern | None:
        if not pattern:
            return None
        try:
            return re.compile(pattern)
        except re.error as exc:
            raise ConfigError(f"parameter {name}: invalid regular expression {pattern!r}: {exc}") from None

    # ------------------------------------------------------------------ discovery
    def _wanted(self, topic: str) -> bool:
        if topic == self._recorded_pub.topic_name:
            return False  # this node's own progress, not the line's
        if topic in self._topics:
            return True
        if self._regex is not None:
            return bool(self._regex.search(topic)) and not (self._exclude and self._exclude.search(topic))
        if self._topics:
            return False
        return not (self._exclude and self._exclude.search(topic))

    def _discover(self) -> None:
        for topic, types in self.get_topic_names_and_types():
            if topic in self._ignored or not self._wanted(topic):
                continue
            if topic in self._subscriptions_by_topic:
                self._check_late_publishers(topic)
                continue
            if len(types) != 1:
                self._ignore(topic, f"has several types {types}")
                continue
            try:
                msg_type = message_class(types[0])
                message_definition(types[0])
            except LookupError as exc:
                self._ignore(topic, str(exc))
                continue
            publishers = self.get_publishers_info_by_topic(topic)
            if not publishers:
                continue  # only subscribers so far: wait for a publisher to learn its QoS
            self._subscribe(topic, types[0], msg_type, publishers)

    def _ignore(self, topic: str, reason: str) -> None:
        self._ignored.add(topic)
        self.get_logger().warning(f"not recording {topic}: {reason}")

    def _subscribe(self, topic: str, type_name: str, msg_type: type, publishers) -> None:
        qos = subscription_qos(publishers, self._depth)
        self._enqueue((topic, None, type_name, qos_profiles_yaml(p.qos_profile for p in publishers), 0), 0)
        enqueue, clock = self._enqueue, self.get_clock()
        seen = self._seen[topic] = [None, 0, 0, len(publishers)]
        if type_name == CLOCK_TYPE:
            self._clock_topics.add(topic)

        def keep(data: bytes, info: dict) -> None:
            sequence = info.get("publication_sequence_number")
            if sequence:
                seen[0] = sequence if seen[0] is None else min(seen[0], sequence)
                seen[1] = max(seen[1], sequence)
            seen[2] += 1
            enqueue((topic, data, clock.now().nanoseconds, info["source_timestamp"], sequence or 0), len(data))

        def on_message(data: bytes, info: dict) -> None:
            keep(data, info)
            handle = subscription.handle
            while True:  # take the whole backlog now: one executor round per burst, not per message
                with handle:
                    taken = handle.take_message(msg_type, True)
                if taken is None:
                    return
                keep(*taken)

        subscription = self.create_subscription(msg_type, topic, on_message, qos, raw=True)
        self._subscriptions_by_topic[topic] = subscription
        self._offered[topic] = len(publishers)
        self.get_logger().info(
            f"recording {topic} [{type_name}] {qos.reliability.name.lower()} {qos.durability.name.lower()}")

    def _check_late_publishers(self, topic: str) -> None:
        count = self.count_publishers(topic)
        if count <= self._offered.get(topic, 0):
            self._offered[topic] = count
            return
        self._offered[topic] = count
        self._seen[topic][3] = max(self._seen[topic][3], count)
        sub_qos = self._subscriptions_by_topic[topic].qos_profile
        for pub in self.get_publishers_info_by_topic(topic):
            offered = pub.qos_profile
            if ((sub_qos.reliability == ReliabilityPolicy.RELIABLE
                 and offered.reliability != ReliabilityPolicy.RELIABLE)
                    or (sub_qos.durability == DurabilityPolicy.TRANSIENT_LOCAL
                        and offered.durability != DurabilityPolicy.TRANSIENT_LOCAL)):
                self.get_logger().warning(
                    f"{topic}: new publisher {pub.node_name} offers {offered.reliability.name.lower()}/"
                    f"{offered.durability.name.lower()}, incompatible with the recording subscription; "
                    "its messages are not recorded")

    # ------------------------------------------------------------------ writing
    def _enqueue(self, item: tuple, size: int) -> None:
        """Hand an item to the writer thread without waiting: a message arriving while more than ``max_buffer_mb``
        is unwritten is dropped (and counted), so a writer that falls behind never makes the middleware hold
        ``queue_depth`` images per topic for us."""
        with self._cond:
            if size and self._buffered > self._max_buffer:
                self._dropped[item[0]] = self._dropped.get(item[0], 0) + 1
                return
            self._buffered += size
            self._items.append(item)
            self._cond.notify()

    def _write_loop(self) -> None:
        writer = self._writer
        last_flush = time.monotonic()
        try:
            while True:
                with self._cond:
                    if not self._items and not self._stopping:
                        self._cond.wait(max(0.01, last_flush + self._flush_period - time.monotonic()))
                    batch, self._items = self._items, collections.deque()
                    stopping = self._stopping
                size = 0
                for topic, data, a, b, sequence in batch:
                    if data is None:
                        writer.add_topic(topic, a, b)
                    else:
                        writer.write(topic, data, a, b, sequence & 0xFFFFFFFF)
                        size += len(data)
                        if topic in self._clock_topics:
                            self._written_clock = clock_stamp(data)
                if size:
                    with self._cond:
                        self._buffered -= size
                        self._cond.notify_all()
                if time.monotonic() - last_flush >= self._flush_period:
                    writer.flush()
                    last_flush = time.monotonic()
                if stopping and not batch:
                    return
        except BaseException as exc:  # noqa: BLE001 - reported by the node
            self._error = exc
            with self._cond:
                self._cond.notify_all()

    def _announce_written_clock(self) -> None:
        """Publish the newest /clock stamp written (when it moved): a line that waits for it never outruns us."""
        written = self._written_clock
        if written is not None and written != self._announced_clock:
            self._announced_clock = written
            self._recorded_pub.publish(RosClock(clock=Time(sec=written[0], nanosec=written[1])))

    def spin(self, stop: threading.Event) -> int:
        """Record until ``stop`` is set, then take what the middleware still holds; 1 if writing failed (the bag
        stays as far as it was written)."""
        executor = SingleThreadedExecutor(context=self.context)
        executor.add_node(self)
        try:
            while not stop.is_set() and rclpy.ok() and self._error is None:
                executor.spin_once(timeout_sec=0.1)
            if self._error is None:
                self.drain(executor)
        except ExternalShutdownException:
            pass
        finally:
            executor.remove_node(self)
        return 0 if self._error is None else 1

    def drain(self, executor, quiet_s: float = 0.3, limit_s: float = 5.0) -> None:
        """Take what the middleware still holds for us before closing: a recorder lagging behind a busy
        graph must not drop the last messages (e.g. the final verdict) because the stop signal came first."""
        deadline = time.monotonic() + limit_s
        last, quiet_since = -1, time.monotonic()
        while time.monotonic() < deadline and time.monotonic() - quiet_since < quiet_s:
            executor.spin_once(timeout_sec=0.05)
            received = sum(seen[2] for seen in self._seen.values())
            if received != last:
                last, quiet_since = received, time.monotonic()

    def drops(self) -> dict[str, tuple[int, int | None]]:
        """Per topic (written, published while subscribed): the publisher's sequence numbers count what it
        sent: published but not written is lost (in transport, or dropped by a full buffer). ``None`` when several
        publishers share the topic
        (their sequence numbers interleave) or the middleware gives none."""
        result = {}
        for topic, (first, last, _received, publishers) in sorted(self._seen.items()):
            published = None if first is None or publishers > 1 else last - first + 1
            result[topic] = (self._writer.counts.get(topic, 0), published)
        return result

    def close(self) -> int:
        """Drain the queue, finish the file with its losses record, log one summary line; 0 if the bag is
        complete, else 1 with one error line (a full disk: what to run to read the bag)."""
        with self._cond:
            self._stopping = True
            self._cond.notify_all()
        self._thread.join()
        duration = time.monotonic() - self._start
        counts, drops = self._writer.counts, self.drops()
        total = sum(counts.values())
        if self._error is None:
            try:
                self._writer.add_metadata("woody.recorder", {
                    "duration_s": f"{duration:.3f}", "messages": str(total),
                    "counts": ",".join(f"{t}={n}" for t, n in sorted(counts.items())),
                    "written/published": ",".join(f"{t}={_drop_text(*d)}" for t, d in drops.items())})
                self._writer.add_metadata(LOSSES_RECORD, losses_record(drops))
                self._writer.close()
            except Exception as exc:  # noqa: BLE001 - reported in one line below
                self._error = exc
        if self._error is not None:
            self.get_logger().error(self._failure_line())
            return 1
        size = self.output.stat().st_size
        missing = sorted(self._topics - set(counts))
        lost = sum(max(0, p - w) for w, p in drops.values() if p is not None)
        self.get_logger().info(
            f"wrote {self.output}: {total} messages, {size / 1e6:.1f} MB on disk in {duration:.1f} s, "
            f"{lost} lost{self._dropped_text()}; written/published per topic: "
            + (", ".join(f"{t} {_drop_text(*d)}" for t, d in drops.items()) or "nothing")
            + (f"; never seen: {', '.join(missing)}" if missing else ""))
        return 0

    def _dropped_text(self) -> str:
        dropped = sum(self._dropped.values())
        if not dropped:
            return ""
        return (f" ({dropped} of them received while more than max_buffer_mb was unwritten: "
                + ", ".join(f"{t} {n}" for t, n in sorted(self._dropped.items())) + ")")

    def _failure_line(self) -> str:
        """The one line naming why the bag could not be written, where, and how to read what it holds."""
        exc = self._error
        received = sum(seen[2] for seen in self._seen.values())
        size = self.output.stat().st_size / 1e6 if self.output.exists() else 0.0
        cause = (f"{exc.strerror} ({errno.errorcode[exc.errno]})" if isinstance(exc, OSError) and exc.errno
                 in errno.errorcode else f"{type(exc).__name__}: {exc}".replace("\n", " "))
        return (f"{FAILURE_PREFIX} {self.output}: {cause}; stopped after {received} messages received, "
                f"{size:.1f} MB on disk; the bag is readable up to its last complete chunk: "
                f"`woody bag recover {self.output} OUT.mcap` writes it complete (OUT on a disk with space)")


def clock_stamp(data: bytes) -> tuple[int, int]:
    """(sec, nanosec) of a serialized rosgraph_msgs/Clock: CDR's 4-byte encapsulation header, then the Time."""
    return struct.unpack_from("<iI" if data[1] == 1 else ">iI", data, 4)


def recorder_failure(log_path) -> str | None:
    """The recorder's one failure line (`FAILURE_PREFIX` ..., e.g. a full disk) in its log, prefixed ``recorder:``
    and without the logger's fields; None when the log holds none."""
    try:
        text = open(log_path, errors="replace").read()
    except OSError:
        return None
    found = [line[line.index(FAILURE_PREFIX):] for line in text.splitlines() if FAILURE_PREFIX in line]
    return f"recorder: {found[-1]}" if found else None


def _drop_text(written: int, published: int | None) -> str:
    if published is None:
        return f"{written}/?"
    return f"{written}/{published}" + (f" (lost {published - written})" if published > written else "")


def main(args: list[str] | None = None) -> int:
    """Record until SIGINT/SIGTERM, then finish the bag. Exit code 0, 2 on bad parameters, 1 on write errors."""
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a file size limit is EFBIG, reported like a full disk
    help_text = usage("recorder").splitlines()[0] + "\n" + __doc__.split("\n\n", 1)[1].split("\n\nTiming")[0]
    return run_node("recorder", Recorder, args, help_text=help_text)


if __name__ == "__main__":
    sys.exit(main())
