"""The real `recorder` entry point against a helper publishing known messages on a private domain.

A stopped recorder (SIGINT or SIGTERM) leaves a complete MCAP that `rosbags`,
`mcap_ros2` and `woody_bag` decode to exactly what was published; a
killed one (SIGKILL) leaves every chunk written before the kill readable.
"""

from __future__ import annotations

import signal
import time
from pathlib import Path

import pytest
from conftest import REPO
from fixtures.known_messages import TOPICS, index_of, known, same
from fixtures.rosbag2_conformance import assert_rosbag2_conformant

from woody_bag.errors import BagError
from woody_bag.reader import read_bag
from woody_bag.schemas import decode
from woody_bag.summary import bag_summary
from woody_tools.processes import NodeProcess, wait_for

COUNT = 20


def start_recorder(domain: int, tmp_path: Path, **params) -> NodeProcess:
    params = {"output": str(tmp_path / "run.mcap"), "discovery_period": 0.2, **params}
    return NodeProcess("recorder", params, domain_id=domain, log_dir=tmp_path)


def stop_with(recorder: NodeProcess, sig: int) -> int:
    recorder.signal(sig)
    recorder.process.wait(15)
    return recorder.stop()


HEALTH = "/diagnostics"


def published(path: Path):
    """(topic, message) of every recorded message the helper published (not the recorder's own health)."""
    for topic, type_name, data, _ in read_bag(path):
        if topic != HEALTH:
            yield topic, decode(type_name, data)


def check_bag(path: Path, topics: list[str], count: int) -> None:
    """Every topic holds messages 0..count-1 in order, equal to what was published, for all three readers."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader

    summary = bag_summary(path)
    assert summary["complete"] and summary["error"] is None
    summary["topics"].pop(HEALTH, None)  # the recorder's own health, recorded with every topic (checked apart)
    assert {t: v["count"] for t, v in summary["topics"].items()} == {t: count for t in topics}
    assert summary["topics"]["/clock"]["type"] == "rosgraph_msgs/msg/Clock"
    assert "log_time" in summary["metadata"]["woody"]
    now = time.time_ns()
    assert now - 120e9 < summary["start_ns"] <= summary["end_ns"] <= now  # without use_sim_time: the system clock
    assert_rosbag2_conformant(path)

    ours: dict[str, list[int]] = {t: [] for t in topics}
    for topic, msg in published(path):
        i = index_of(topic, msg)
        assert msg == known(topic, i), (topic, i)
        ours[topic].append(i)
    assert ours == {t: list(range(count)) for t in topics}

    seen = 0
    with AnyReader([path]) as reader:
        assert sorted(c.topic for c in reader.connections if c.topic != HEALTH) == sorted(topics)
        for connection, _, raw in reader.messages([c for c in reader.connections if c.topic != HEALTH]):
            msg = reader.deserialize(raw, connection.msgtype)
            same(known(connection.topic, index_of(connection.topic, msg)), msg, connection.topic)
            seen += 1
    assert seen == count * len(topics)

    seen = 0
    with open(path, "rb") as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory()])
        for _, channel, _, decoded in reader.iter_decoded_messages(topics=topics):
            same(known(channel.topic, index_of(channel.topic, decoded)), decoded, channel.topic)
            seen += 1
    assert seen == count * len(topics)


@pytest.mark.parametrize("sig,params,expected", [
    (signal.SIGINT, {}, sorted(TOPICS)),
    (signal.SIGTERM, {"topics": ["/clock", "vision/tracks"], "topic_regex": "^/(line|top_camera/color)/"},
     ["/clock", "/line/ground_truth", "/top_camera/color/camera_info", "/top_camera/color/image_raw",
      "/vision/tracks"]),
])
def test_stopped_recorder_leaves_a_complete_bag(ros_domain, spawn_helper, tmp_path, sig, params, expected):
    recorder = start_recorder(ros_domain, tmp_path, **params)
    try:
        publisher = spawn_helper("publish_known", "--count", str(COUNT), "--rate", "20", "--wait-topics", *expected)
        publisher.wait(30)
        assert publisher.returncode == 0, (tmp_path / "publish_known.log").read_text()
        assert recorder.alive(), recorder.log_tail()
        assert stop_with(recorder, sig) == 0, recorder.log_tail()
    finally:
        recorder.stop()
    log = recorder.log_tail(5)
    assert "messages" in log and "/vision/tracks 20/20" in log, log  # the closing line: written/published
    assert " MB on disk " in log and " 0 lost; " in log, log
    # /line/ground_truth message 0 was latched before the recorder subscribed: recorded all the same
    check_bag(tmp_path / "run.mcap", expected, COUNT)
    health = bag_summary(tmp_path / "run.mcap")["topics"].get(HEALTH)
    assert (health is not None and health["count"] >= 1) == (not params)  # its own health, with every topic


def test_killed_recorder_leaves_its_written_chunks_readable(ros_domain, spawn_helper, tmp_path):
    from mcap.records import Message
    from mcap.stream_reader import StreamReader

    flush_period = 0.25
    recorder = start_recorder(ros_domain, tmp_path, flush_period=flush_period)
    log = tmp_path / "publish_known.log"
    try:
        spawn_helper("publish_known", "--count", "400", "--rate", "40", "--small-images")
        assert wait_for(lambda: log.exists() and "sent 60 " in log.read_text(), timeout=30), log.read_text()
        time.sleep(1.0)
        killed_at = time.time()
        recorder.signal(signal.SIGKILL)
        recorder.process.wait(5)
    finally:
        recorder.stop()
    sent = [line.split() for line in log.read_text().splitlines() if line.startswith("sent ")]
    # every round published well before the kill (one flush period plus delivery) must be on disk
    safe = max(int(n) for n, t in ((s[1], float(s[2])) for s in sent) if t < killed_at - flush_period - 0.3)
    assert safe >= 60

    path = tmp_path / "run.mcap"
    clock, read = _read_until_truncated(path)
    assert clock == list(range(len(clock))) and len(clock) >= safe, (len(clock), safe)
    assert read >= safe * len(TOPICS), (read, safe)

    # mcap's own streaming reader recovers the same chunks
    recovered = 0
    with open(path, "rb") as handle:
        try:
            for record in StreamReader(handle).records:
                recovered += isinstance(record, Message)
        except Exception:  # noqa: BLE001 - the cut-off end
            pass
    assert recovered >= safe * len(TOPICS)
    summary = bag_summary(path)
    assert not summary["complete"] and "truncated" in summary["error"]

    _check_recovered(path, tmp_path / "fixed.mcap", read, len(clock))


def _read_until_truncated(path) -> tuple[list[int], int]:
    """Reads a cut bag up to its cut: the /clock indices seen and the number of messages read."""
    clock: list[int] = []
    read = 0
    with pytest.raises(BagError, match=rf"{path.name}: truncated after \d+ messages at t=[\d.]+s"):
        for topic, msg in published(path):
            assert msg == known(topic, index_of(topic, msg), small_images=True)
            clock += [index_of(topic, msg)] if topic == "/clock" else []
            read += 1
    return clock, read


def _check_recovered(path, fixed, read: int, clock_count: int) -> None:
    """`woody bag recover` turns a cut bag into a complete, indexed bag that rosbags and mcap open, keeping
    every message a reader got before the cut (the last round of topics may be cut part-way)."""
    import subprocess

    from mcap.reader import make_reader
    from rosbags.highlevel import AnyReader

    from woody_tools.processes import entry_point

    result = subprocess.run([entry_point("woody"), "bag", "recover", str(path), str(fixed)], capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0 and "truncated after" in result.stdout, result.stderr
    assert bag_summary(fixed)["complete"] and bag_summary(fixed)["message_count"] >= read
    with AnyReader([fixed]) as reader:
        clock_connections = [c for c in reader.connections if c.topic == "/clock"]
        assert len(list(reader.messages(connections=clock_connections))) == clock_count
    with open(fixed, "rb") as handle:
        assert make_reader(handle).get_summary().statistics.message_count == bag_summary(fixed)["message_count"]


def test_bad_parameters_fail_with_one_clear_line(ros_domain, tmp_path):
    bad_regex = start_recorder(ros_domain, tmp_path / "a", topic_regex="(")
    bad_output = start_recorder(ros_domain, tmp_path / "b", output="/proc/woody/run.mcap")
    assert bad_regex.process.wait(20) == 2
    assert bad_output.process.wait(20) == 2
    assert "invalid regular expression" in bad_regex.log_tail()
    assert "/proc/woody/run.mcap: cannot create bag" in bad_output.log_tail()
    for proc in (bad_regex, bad_output):
        assert "Traceback" not in proc.log_tail(50)
        proc.stop()


# ---------------------------------------------------------------- woody_bag without a ROS graph

def test_message_definition_is_rosbag2s_ros2msg_text():
    from woody_bag.schemas import message_definition

    text = message_definition("woody_msgs/msg/FilletTrackArray")
    assert text == message_definition("woody_msgs/FilletTrackArray")
    own = (REPO / "src" / "woody_msgs" / "msg" / "FilletTrackArray.msg").read_text()
    assert text.startswith(own)
    blocks = text.split("=" * 80 + "\n")
    assert [b.splitlines()[0] for b in blocks[1:]] == [
        "MSG: std_msgs/Header", "MSG: builtin_interfaces/Time", "MSG: woody_msgs/FilletTrack"]
    assert "uint32 nanosec" in blocks[2]


def _bag_of_known(path: Path, **kw) -> list[tuple[str, int]]:
    from rclpy.serialization import serialize_message

    from woody_bag.writer import BagWriter

    written = []
    with BagWriter(path, **kw) as bag:
        for topic in TOPICS:
            bag.add_topic(topic, f"{TOPICS[topic][0].__module__.split('.')[0]}/msg/{TOPICS[topic][0].__name__}")
        for i in range(30):
            for topic in TOPICS:
                bag.write(topic, serialize_message(known(topic, i, small_images=True)), 10**18 + i * 10**7)
                written.append((topic, i))
    return written


@pytest.mark.parametrize("compression", ["zstd", "none"])
def test_a_bag_cut_anywhere_reads_as_a_clean_prefix(tmp_path, compression):
    full = tmp_path / "full.mcap"
    written = _bag_of_known(full, chunk_size=8000, compression=compression)
    data = full.read_bytes()
    cut = tmp_path / "cut.mcap"
    for size in range(0, len(data), max(1, len(data) // 97)):
        cut.write_bytes(data[:size])
        got = []
        try:
            for topic, type_name, raw, _ in read_bag(cut):
                msg = decode(type_name, raw)
                got.append((topic, index_of(topic, msg)))
                assert msg == known(topic, got[-1][1], small_images=True)
        except BagError as exc:
            assert str(exc).startswith(f"{cut}: ") and "\n" not in str(exc)
            assert "truncated after" in str(exc) or "empty file" in str(exc)
        assert got == written[:len(got)], size
    assert len(got) > 0.9 * len(written)


def test_a_damaged_chunk_stops_reading_with_one_line(tmp_path):
    full = tmp_path / "full.mcap"
    _bag_of_known(full, chunk_size=8000)
    from mcap.reader import make_reader

    with open(full, "rb") as handle:
        chunk = make_reader(handle).get_summary().chunk_indexes[1]
    data = bytearray(full.read_bytes())
    middle = chunk.chunk_start_offset + chunk.chunk_length // 2
    data[middle:middle + 32] = bytes(32)
    full.write_bytes(bytes(data))
    with pytest.raises(BagError, match=r"full\.mcap: corrupt after \d+ messages at t=[\d.]+s \("):
        for _topic, type_name, raw, _ in read_bag(full):
            decode(type_name, raw)


def test_a_recorder_at_its_file_size_limit_stops_with_one_line_and_a_readable_bag(ros_domain, spawn_helper, tmp_path):
    """RLIMIT_FSIZE on the running recorder stands in for a full disk (EFBIG and ENOSPC are handled alike)."""
    import resource

    limit = 60_000
    recorder = start_recorder(ros_domain, tmp_path, flush_period=0.25)
    resource.prlimit(recorder.process.pid, resource.RLIMIT_FSIZE, (limit, limit))
    try:
        spawn_helper("publish_known", "--count", "400", "--rate", "40", "--small-images")
        assert recorder.process.wait(60) == 1, recorder.log_tail()
    finally:
        recorder.stop()
    log = recorder.log_path.read_text()
    errors = [line for line in log.splitlines() if "[ERROR]" in line]
    bag = tmp_path / "run.mcap"
    assert "Traceback" not in log and len(errors) == 1, log
    assert f"stopped recording: {bag}: File too large (EFBIG)" in errors[0], errors[0]
    assert f"`woody bag recover {bag} OUT.mcap`" in errors[0], errors[0]
    assert bag.stat().st_size < limit  # cut back to its last whole record
    clock, read = _read_until_truncated(bag)
    assert clock == list(range(len(clock))) and len(clock) >= 5, clock
    _check_recovered(bag, tmp_path / "fixed.mcap", read, len(clock))
