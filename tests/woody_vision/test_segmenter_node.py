"""woody_vision.segmenter_node with colour and depth stamps that differ, as a real camera sends them.

In the node (no spin): every depth frame is answered with one FilletTrackArray, once and in order, whether colour
comes or stops, and the depth-only configuration never waits for colour. Through the entry points: the sample bag
replayed into one segmenter (colour outline) and grader, aligned and then with its colour stamps shifted by up to
half a frame, gives the same verdicts every time.
"""

from __future__ import annotations

import itertools
import re
from pathlib import Path
from types import SimpleNamespace

import pytest
from conftest import REPO, spin_until
from rclpy.qos import QoSProfile, ReliabilityPolicy

from woody_common.stamps import nanoseconds_to_stamp, stamp_to_nanoseconds, stamp_to_seconds
from woody_tools.processes import NodeProcess
from woody_vision.frame_pairing import HELD_DEPTH_FRAMES

pytestmark = pytest.mark.ros
"""Builds nodes on a private domain and starts node entry points as processes."""

SAMPLE = REPO / "bags" / "sample" / "line.mcap"
DEPTH, DEPTH_INFO = "/top_camera/depth/image_raw", "/top_camera/depth/camera_info"
COLOUR = "/top_camera/color/image_raw"
OFFSETS_MS = (1, 10, 16, -10)
"""Colour stamps minus depth stamps replayed; half the sample's 30 Hz frame interval is 16.7 ms."""
CUT_S = 2.1
"""Sim time the replayed bags end at: just past the sample's verdicts (its three fillets cross the roller edge
together at 2.0 s)."""
RATE = 0.25
"""Replay speed: the frames come at about 10 Hz (the sample's start was recorded at 1.3x real time, in bursts), so
a loaded machine's segmenter, which takes 0.1-0.2 s to learn the background and up to 30 ms a frame, never loses
one from its queue of 10; a lost frame would change the verdicts compared exactly."""
VISION = {"use_sim_time": True, "lanes": 3, "image_qos": "reliable"}
"""Reliable images: a frame lost in transit would change a verdict, and the comparison is exact."""
SEGMENTER = {**VISION, "color_threshold": 20.0}
GRADER = {**VISION, "use_side_view": False}
VALUES = ("score", "line_phi", "phi", "hu_term", "solidity_term")


def sample_frames(count: int) -> list:
    """The sample's first ``count`` top-camera frames as (topic, message), each frame's colour image, then its
    calibration and depth image (the order a recording has them in depends on the machine that made it)."""
    from woody_bag.reader import read_bag
    from woody_bag.schemas import decode

    frames = read_bag(SAMPLE, topics=[DEPTH, DEPTH_INFO, COLOUR])
    early = itertools.islice(frames, 3 * count + 30)  # enough to hold every message of the first ``count`` frames
    decoded = [(topic, decode(type_name, data)) for topic, type_name, data, _ in early]
    order = {COLOUR: 0, DEPTH_INFO: 1, DEPTH: 2}
    decoded.sort(key=lambda frame: (stamp_to_nanoseconds(frame[1].header.stamp), order[frame[0]]))
    return decoded[: 3 * count]


@pytest.fixture
def segmenter(ros_domain):
    """``make(**params)``: a Segmenter built in this process with those parameters, and the list its tracks go to."""
    import rclpy

    from woody_vision.segmenter_node import Segmenter

    nodes = []

    def make(**params) -> tuple[Segmenter, list]:
        rclpy.init(args=["--ros-args", *(a for k, v in params.items() for a in ("-p", f"{k}:={v}"))],
                   domain_id=ros_domain)
        nodes.append(Segmenter())
        published: list = []
        nodes[-1].tracks_pub = SimpleNamespace(publish=published.append)
        return nodes[-1], published

    yield make
    for node in nodes:
        node.destroy_node()
    rclpy.try_shutdown()


def feed(node, frames: list, colour_until: int, offset_ns: int = 0):
    """Give the node the frames (colour only for the first ``colour_until`` depth frames, stamped ``offset_ns``
    from them); yields each depth frame's stamp once the node has it."""
    depth_frames = 0
    for topic, msg in frames:
        if topic == DEPTH_INFO:
            node.on_camera_info(msg)
        elif topic == DEPTH:
            depth_frames += 1
            node.on_depth(msg)
            yield stamp_to_nanoseconds(msg.header.stamp)
        elif depth_frames < colour_until:
            msg.header.stamp = nanoseconds_to_stamp(stamp_to_nanoseconds(msg.header.stamp) + offset_ns)
            node.on_color(msg)


def answered(published: list) -> list[int]:
    return [stamp_to_nanoseconds(m.header.stamp) for m in published]


def test_depth_only_answers_every_depth_frame_at_once_when_the_colour_stream_stops(segmenter):
    node, published = segmenter(color_threshold=0.0, publish_debug_image=True)  # subscribed to colour, not waiting
    given = []
    for stamp in feed(node, sample_frames(20), colour_until=5):
        given.append(stamp)
        assert answered(published) == given


def test_the_colour_outline_answers_every_depth_frame_once_in_order_when_the_colour_stream_stops(segmenter, capsys):
    node, published = segmenter(color_threshold=20.0)
    given = list(feed(node, sample_frames(20), colour_until=10, offset_ns=10_000_000))
    assert answered(published) == given[: 20 - HELD_DEPTH_FRAMES]
    assert all(m.tracks == [] for m in published[10:])
    node.close()
    summary = capsys.readouterr().out
    skipped = 10 - HELD_DEPTH_FRAMES  # the last ten came without colour; the held ones are never answered
    assert f"20 depth frames received, 0 rejected, {skipped} skipped without their colour frame ({skipped} without " \
           "one within the tolerance, ±16.7 ms)" in summary, summary


def colour_late(frames: list, late: int) -> list:
    """The frames with each colour image delivered after the depth frame ``late`` frames after its own."""
    depth_seen, waiting, out = 0, [], []
    for topic, msg in frames:
        if topic == COLOUR:
            waiting.append((depth_seen + late, (topic, msg)))
            continue
        out.append((topic, msg))
        if topic == DEPTH:
            depth_seen += 1
            out += [frame for due, frame in waiting if due <= depth_seen]
            waiting = [(due, frame) for due, frame in waiting if due > depth_seen]
    return out + [frame for _, frame in waiting]


@pytest.mark.parametrize("wait, paired", [(HELD_DEPTH_FRAMES, False), (8, True)])
def test_colour_frames_late_pair_with_their_depth_frames_within_color_wait_frames(segmenter, capsys, wait, paired):
    """A driver whose colour arrives six depth frames after its depth frame: ``color_wait_frames`` 8 pairs every
    depth frame whose colour came, the default 4 has to decide them before their colour comes and skips them."""
    node, published = segmenter(color_threshold=20.0, color_wait_frames=wait)
    given = list(feed(node, colour_late(sample_frames(20), late=6), colour_until=20))
    node.close()
    summary = capsys.readouterr().out
    assert ("20 depth frames received, 0 rejected, 0 skipped without their colour frame" in summary) == paired, \
        summary
    if paired:  # the last six wait for colour the feed never delivers
        assert answered(published) == given[:14]


def shifted(bag: Path, offset_ms: int) -> tuple[Path, list[int]]:
    """The sample's top-camera topics and /clock up to CUT_S of sim time, each colour image stamped ``offset_ms``
    from its depth frame; the bag and its depth stamps."""
    from rclpy.serialization import serialize_message

    from woody_bag.reader import read_bag
    from woody_bag.schemas import decode
    from woody_bag.writer import BagWriter

    depth_stamps = []
    with BagWriter(bag) as writer:
        for topic, type_name, data, log_time in read_bag(SAMPLE, topics=[DEPTH, DEPTH_INFO, COLOUR, "/clock"]):
            msg = decode(type_name, data)
            if stamp_to_seconds(msg.clock if topic == "/clock" else msg.header.stamp) > CUT_S:
                break
            if topic not in writer.topics:
                writer.add_topic(topic, type_name)
            if topic == COLOUR:
                msg.header.stamp = nanoseconds_to_stamp(stamp_to_nanoseconds(msg.header.stamp) + offset_ms * 10**6)
                data = serialize_message(msg)
            elif topic == DEPTH:
                depth_stamps.append(stamp_to_nanoseconds(msg.header.stamp))
            writer.write(topic, data, log_time)
    return bag, depth_stamps


def replay(bag: Path, ros_node, ros_domain: int, log_dir: Path, heard: dict[str, list]) -> dict[str, list]:
    """Replay the bag into the running nodes; what they published meanwhile (``heard``'s lists grow)."""
    start = {name: len(got) for name, got in heard.items()}
    player = NodeProcess("woody", None, domain_id=ros_domain, log_dir=log_dir,
                         extra_args=["replay", str(bag), "--rate", str(RATE), "--discovery", "0",
                                     "--wait-for-subscribers", "30", "--progress", "0"])
    spin_until(ros_node, lambda: not player.alive(), timeout=120.0)
    spin_until(ros_node, lambda: len(heard["verdicts"]) >= start["verdicts"] + 3, timeout=10.0)
    assert player.stop() == 0, player.log_tail()
    return {name: got[start[name]:] for name, got in heard.items()}


def said(verdicts: list, first_id: int) -> list[tuple]:
    """What the verdicts say, by crossing stamp; fillet ids counted from the pass's first track id."""
    return sorted((stamp_to_seconds(v.header.stamp), v.lane, v.fillet_id - first_id, v.classification, v.grade,
                   v.unscored_reason, *(round(getattr(v, f), 9) for f in VALUES)) for v in verdicts)


def test_colour_stamps_up_to_half_a_frame_off_give_the_aligned_verdicts(ros_node, ros_domain, tmp_path):
    from woody_msgs.msg import FilletTrackArray, FilletVerdict

    heard: dict[str, list] = {"verdicts": [], "tracks": []}
    reliable = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    ros_node.create_subscription(FilletVerdict, "/grading/verdicts", heard["verdicts"].append, reliable)
    ros_node.create_subscription(FilletTrackArray, "/vision/tracks", heard["tracks"].append, reliable)
    bags = {ms: shifted(tmp_path / f"shifted{ms}.mcap", ms) for ms in (0, *OFFSETS_MS)}
    nodes = [NodeProcess("segmenter", SEGMENTER, domain_id=ros_domain, log_dir=tmp_path),
             NodeProcess("grader", GRADER, domain_id=ros_domain, log_dir=tmp_path)]
    passes = {}
    try:
        assert spin_until(ros_node, lambda: ros_node.count_publishers("/vision/tracks") >= 1
                          and ros_node.count_subscribers("/vision/tracks") >= 2, timeout=60.0)
        for ms, (bag, depth_stamps) in bags.items():
            got = replay(bag, ros_node, ros_domain, tmp_path / f"replay{ms}", heard)
            answered = [stamp_to_nanoseconds(m.header.stamp) for m in got["tracks"]]
            # once and in order; only the last frames may still wait for a colour frame after the bag's end
            assert answered == depth_stamps[: len(answered)], f"colour {ms:+d} ms: frames lost or answered twice"
            assert len(answered) >= len(depth_stamps) - HELD_DEPTH_FRAMES, f"colour {ms:+d} ms"
            passes[ms] = said(got["verdicts"], min(t.id for m in got["tracks"] for t in m.tracks))
    finally:
        for node in nodes:
            node.stop()
    log = nodes[0].log_path.read_text()
    aligned = passes.pop(0)
    assert len(aligned) == 3 and all(v[3] != FilletVerdict.CLASS_UNSCORED for v in aligned), log
    for ms, got in passes.items():
        assert got == aligned, f"colour {ms:+d} ms\n{log}"
    skipped = re.search(r"0 rejected, (\d+) skipped without their colour frame", log)
    assert skipped and int(skipped[1]) <= len(OFFSETS_MS), log  # at most a pass's first, before the interval is known
