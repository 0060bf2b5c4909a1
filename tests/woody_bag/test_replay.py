"""`woody replay` (woody_tools.commands.replay.run in its own process) into subscribers on a private domain."""

from __future__ import annotations

import argparse
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import FIXTURES, fixture_env, spin_until
from fixtures.known_messages import TOPICS, index_of, known
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message

from woody_bag import player
from woody_bag.errors import BagError
from woody_bag.reader import read_bag
from woody_bag.writer import BagWriter
from woody_tools.commands import replay

T0 = 1_700_000_000 * 10**9  # log time of the first message (wall clock of a past recording)
TRACKS = "/vision/tracks"
VERDICTS = "/grading/verdicts"
TRACK_TIMES = [0.1 * i for i in range(10)]          # s after T0
VERDICT_TIMES = [0.05, 0.3, 0.35, 0.8]
CLOCK_TIMES = [0.05 * i for i in range(20)]          # recorded /clock: sim ran at half real time


def sim_clock(i: int):
    from rosgraph_msgs.msg import Clock

    msg = Clock()
    msg.clock.sec, msg.clock.nanosec = divmod(500 * 10**9 + i * 25_000_000, 10**9)
    return msg


IMAGES = "/top_camera/color/image_raw"


def write_bag(path: Path, with_clock: bool = True, images: bool = False, **kw) -> Path:
    with BagWriter(path, **kw) as bag:
        bag.add_topic(TRACKS, "woody_msgs/msg/FilletTrackArray")
        bag.add_topic(VERDICTS, "woody_msgs/msg/FilletVerdict")
        events = [(t, TRACKS, known(TRACKS, i)) for i, t in enumerate(TRACK_TIMES)]
        events += [(t, VERDICTS, known(VERDICTS, i)) for i, t in enumerate(VERDICT_TIMES)]
        if with_clock:
            bag.add_topic("/clock", "rosgraph_msgs/msg/Clock")
            events += [(t, "/clock", sim_clock(i)) for i, t in enumerate(CLOCK_TIMES)]
        if images:  # bulk, so that half the file is half the data
            bag.add_topic(IMAGES, "sensor_msgs/msg/Image")
            events += [(t + 0.01, IMAGES, known(IMAGES, i, small_images=True)) for i, t in enumerate(TRACK_TIMES)]
        for t, topic, msg in sorted(events, key=lambda e: e[0]):
            bag.write(topic, serialize_message(msg), T0 + round(t * 1e9))
    return path


class Listener:
    """Subscribes to the bag's topics; keeps (arrival monotonic time, message) per topic."""

    def __init__(self, node) -> None:
        from rosgraph_msgs.msg import Clock

        self.node = node
        self.got: dict[str, list] = {TRACKS: [], VERDICTS: [], "/clock": []}
        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        for topic, cls in ((TRACKS, TOPICS[TRACKS][0]), (VERDICTS, TOPICS[VERDICTS][0]), ("/clock", Clock)):
            node.create_subscription(cls, topic, lambda m, t=topic: self.got[t].append((time.monotonic(), m)), qos)

    def spin_while(self, proc: subprocess.Popen, timeout: float = 20.0) -> None:
        spin_until(self.node, lambda: proc.poll() is not None, timeout)
        spin_until(self.node, lambda: False, 0.3)  # stragglers


def start_replay(domain: int, tmp_path: Path, *args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, str(FIXTURES / "replay_cli.py"), *args,
                             "--wait-for-subscribers", "10", "--progress", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=fixture_env(domain))


def assert_timing(arrivals: list[float], expected: list[float], rate: float) -> None:
    """Arrival offsets from the first message within ±20 % of the recorded offsets / rate."""
    for got, want in zip(arrivals, expected):
        got -= arrivals[0]
        want = (want - expected[0]) / rate
        assert abs(got - want) <= 0.2 * want + 0.015, (got, want)


def test_replay_reproduces_messages_timing_and_recorded_clock(ros_node, ros_domain, tmp_path):
    bag = write_bag(tmp_path / "line.mcap")
    listener = Listener(ros_node)
    proc = start_replay(ros_domain, tmp_path, str(bag))
    listener.spin_while(proc)
    out, err = proc.communicate()
    assert proc.returncode == 0, err
    assert err == ""
    tracks, verdicts, clock = (listener.got[t] for t in (TRACKS, VERDICTS, "/clock"))
    assert [m for _, m in tracks] == [known(TRACKS, i) for i in range(len(TRACK_TIMES))]
    assert [m for _, m in verdicts] == [known(VERDICTS, i) for i in range(len(VERDICT_TIMES))]
    # the recorded sim time, not the log times
    assert [m for _, m in clock] == [sim_clock(i) for i in range(len(CLOCK_TIMES))]
    assert_timing([t for t, _ in tracks], TRACK_TIMES, 1.0)
    merged = sorted([(t, "v") for t, _ in verdicts] + [(t, "t") for t, _ in tracks])
    assert_timing([t for t, _ in merged], sorted(VERDICT_TIMES + TRACK_TIMES), 1.0)
    assert "done: 34 messages" in out


def test_rate_topic_filter_and_synthesised_clock(ros_node, ros_domain, tmp_path):
    bag = write_bag(tmp_path / "noclock.mcap", with_clock=False)
    listener = Listener(ros_node)
    proc = start_replay(ros_domain, tmp_path, str(bag), "--rate", "2", "--topics", VERDICTS)
    listener.spin_while(proc)
    _, err = proc.communicate()
    assert proc.returncode == 0, err
    assert listener.got[TRACKS] == []
    verdicts = listener.got[VERDICTS]
    assert [m for _, m in verdicts] == [known(VERDICTS, i) for i in range(len(VERDICT_TIMES))]
    assert_timing([t for t, _ in verdicts], VERDICT_TIMES, 2.0)
    # /clock synthesised from the log times: monotonic, spanning the played part of the bag
    stamps = [m.clock.sec * 10**9 + m.clock.nanosec for _, m in listener.got["/clock"]]
    assert len(stamps) >= 10 and stamps == sorted(stamps)
    assert stamps[0] >= T0 + 0.05e9 - 1 and stamps[-1] == T0 + round(0.8e9)


def test_topics_live_nodes_publish_are_not_replayed_unless_asked(ros_node, ros_domain, tmp_path):
    """Replaying into a running graph: the live grader's verdicts and clock are not doubled by the bag's."""
    from rosgraph_msgs.msg import Clock

    bag = write_bag(tmp_path / "line.mcap")
    ros_node.create_publisher(TOPICS[VERDICTS][0], VERDICTS, 10)  # stands in for a live grader
    ros_node.create_publisher(Clock, "/clock", 10)  # and a live simulator
    listener = Listener(ros_node)
    proc = start_replay(ros_domain, tmp_path, str(bag), "--discovery", "15")
    listener.spin_while(proc, timeout=40.0)
    _, err = proc.communicate()
    assert proc.returncode == 0, err
    assert listener.got[VERDICTS] == [] and listener.got["/clock"] == [], err
    assert len(listener.got[TRACKS]) == len(TRACK_TIMES)
    assert err.startswith("replay: not replaying topics live nodes publish")
    assert "/grading/verdicts (by pytest_probe)" in err
    proc = start_replay(ros_domain, tmp_path, str(bag), "--keep-live", "--exclude", TRACKS)
    listener.spin_while(proc)
    assert proc.communicate()[1] == "" and proc.returncode == 0
    assert len(listener.got[VERDICTS]) == len(VERDICT_TIMES) and len(listener.got[TRACKS]) == len(TRACK_TIMES)


def test_a_live_publisher_that_appears_during_playback_stops_that_topic(ros_node, ros_domain, tmp_path):
    """A grader started after the replay: from the moment it is seen, the bag's verdicts and clock stop (one line
    each time), the other topics play on."""
    from rosgraph_msgs.msg import Clock

    bag = tmp_path / "long.mcap"
    with BagWriter(bag) as writer:
        for topic, type_name in ((TRACKS, "woody_msgs/msg/FilletTrackArray"),
                                 (VERDICTS, "woody_msgs/msg/FilletVerdict"), ("/clock", "rosgraph_msgs/msg/Clock")):
            writer.add_topic(topic, type_name)
        for i in range(40):  # 6 s: a message of each topic every 0.15 s
            for topic, msg in ((TRACKS, known(TRACKS, i)), (VERDICTS, known(VERDICTS, i)), ("/clock", sim_clock(i))):
                writer.write(topic, serialize_message(msg), T0 + i * 150_000_000)
    listener = Listener(ros_node)
    proc = start_replay(ros_domain, tmp_path, str(bag), "--discovery", "0")
    assert spin_until(ros_node, lambda: len(listener.got[VERDICTS]) >= 5, timeout=30), proc.communicate()
    ros_node.create_publisher(TOPICS[VERDICTS][0], VERDICTS, 10)  # the live grader comes up
    ros_node.create_publisher(Clock, "/clock", 10)  # and a live simulator
    appeared = time.monotonic()
    listener.spin_while(proc, timeout=40.0)
    _, err = proc.communicate()
    assert proc.returncode == 0, err
    grace = 1.0  # discovery of the new publishers by the player, and its check period
    assert [t for t, _ in listener.got[VERDICTS] if t > appeared + grace] == [], err
    assert [t for t, _ in listener.got["/clock"] if t > appeared + grace] == [], err
    assert 5 <= len(listener.got[VERDICTS]) < 40 and len(listener.got[TRACKS]) == 40, err
    lines = err.splitlines()
    assert lines and all(line.startswith("replay: live nodes publish ") for line in lines), err
    assert "/grading/verdicts (by pytest_probe)" in err and "/clock (by pytest_probe)" in err, err
    assert "not replayed from t=" in lines[0], err


def test_a_namespace_moves_every_recorded_topic_and_the_clock():
    assert player.moved("/grading/verdicts", "") == "/grading/verdicts"
    assert player.moved("/grading/verdicts", "/line2/") == "/line2/grading/verdicts"
    assert player.moved("/clock", "line2") == "/line2/clock"


def test_truncated_bag_plays_its_readable_part(ros_node, ros_domain, tmp_path):
    full = write_bag(tmp_path / "full.mcap", images=True, chunk_size=20_000, compression="none")
    data = full.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    readable = []
    with pytest.raises(BagError) as error:
        for topic, *_ in read_bag(cut, topics=[TRACKS, VERDICTS]):
            readable.append(topic)
    assert 3 < len(readable) < 12, readable
    listener = Listener(ros_node)
    proc = start_replay(ros_domain, tmp_path, str(cut), "--rate", "4", "--no-clock", "--topics", TRACKS, VERDICTS)
    listener.spin_while(proc)
    _, err = proc.communicate()
    assert proc.returncode == 0, err
    assert err.splitlines() == [f"replay: {error.value}; stopped there"]
    for topic in (TRACKS, VERDICTS):
        assert [m for _, m in listener.got[topic]] == [known(topic, i) for i in range(readable.count(topic))]
    assert listener.got["/clock"] == []


def test_loop_until_interrupted(ros_node, ros_domain, tmp_path):
    bag = write_bag(tmp_path / "loop.mcap")
    listener = Listener(ros_node)
    proc = start_replay(ros_domain, tmp_path, str(bag), "--loop", "--rate", "5", "--topics", TRACKS)
    assert spin_until(ros_node, lambda: len(listener.got[TRACKS]) >= 25, timeout=20)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=10)
    assert proc.returncode == 0, err
    assert "stopped:" in out
    indices = [index_of(TRACKS, m) for _, m in listener.got[TRACKS]]
    assert indices[:25] == (list(range(10)) * 3)[:25]


@pytest.mark.parametrize("make,args,message", [
    (None, [], "replay: {bag}: no such file"),
    (lambda p: p.write_text("not a bag"), [], "replay: {bag}: not an MCAP file"),
    (lambda p: p.write_bytes(b""), [], "replay: {bag}: empty file, not an MCAP bag"),
    (lambda p: write_bag(p), ["--topics", "/nope"], "replay: {bag}: holds none of /nope (it has /clock "
                                                   "/grading/verdicts /vision/tracks)"),
    (lambda p: write_bag(p), ["--rate", "0"], "replay: --rate must be > 0 (got 0.0)"),
])
def test_unplayable_bags_exit_2_with_one_line(tmp_path, capsys, make, args, message):
    bag = tmp_path / "x.mcap"
    if make:
        make(bag)
    parser = argparse.ArgumentParser()
    replay.add_arguments(parser)
    assert replay.run(parser.parse_args([str(bag), *args])) == 2
    out, err = capsys.readouterr()
    assert out == "" and err == message.format(bag=bag) + "\n"


def test_a_topic_recorded_with_an_older_woody_msgs_definition_is_skipped_with_one_line(tmp_path, capsys, monkeypatch):
    from woody_bag import writer

    current = writer.message_definition
    monkeypatch.setattr(writer, "message_definition",
                        lambda t: current(t).replace("int32[] contour_uv", "geometry_msgs/Polygon contour"))
    bag = write_bag(tmp_path / "old.mcap", with_clock=False)
    monkeypatch.undo()
    parser = argparse.ArgumentParser()
    replay.add_arguments(parser)
    assert replay.run(parser.parse_args([str(bag), "--topics", TRACKS, "--no-clock"])) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(f"replay: {bag}: nothing playable in the selected topics (skipping "
                                               f"{TRACKS}: recorded with an older woody_msgs/msg/FilletTrackArray")


def test_every_publisher_the_clock_included_waits_for_its_last_messages_to_be_acknowledged(
        ros_domain, tmp_path, monkeypatch):
    from rclpy.publisher import Publisher

    acknowledged = []
    monkeypatch.setattr(Publisher, "wait_for_all_acked", lambda self, timeout: acknowledged.append(self.topic_name))
    monkeypatch.setenv("ROS_DOMAIN_ID", str(ros_domain))
    bag = write_bag(tmp_path / "line.mcap")
    parser = argparse.ArgumentParser()
    replay.add_arguments(parser)
    assert replay.run(parser.parse_args([str(bag), "--rate", "10", "--keep-live", "--quiet"])) == 0
    assert sorted(acknowledged) == sorted(["/clock", TRACKS, VERDICTS])


def test_a_line_bag_plays_at_the_lines_pace_not_the_recordings(ros_node, ros_domain, tmp_path):
    """The recorder writes log times on the line's clock (sim time), so a bag plays at the line's own pace whatever
    real-time factor its recording ran at (a loaded machine records a 6-lane line at about 0.3x): the committed
    sample's /clock arrives as far apart in wall time as its sim stamps are."""
    sample = Path(__file__).resolve().parents[2] / "bags" / "sample" / "line.mcap"
    listener = Listener(ros_node)
    proc = start_replay(ros_domain, tmp_path, str(sample), "--topics", "/clock")
    listener.spin_while(proc, timeout=60.0)
    _, err = proc.communicate()
    assert proc.returncode == 0, err
    arrivals, sim = [], []
    for arrival, msg in listener.got["/clock"]:  # a tick a second of sim time: arrival jitter is small against it
        stamp = msg.clock.sec + msg.clock.nanosec * 1e-9
        if not sim or stamp >= sim[-1] + 1.0:
            arrivals.append(arrival)
            sim.append(stamp)
    assert len(sim) >= 6
    assert_timing(arrivals, sim, 1.0)
