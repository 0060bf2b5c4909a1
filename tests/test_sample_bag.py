"""The committed sample bag: readable by independent readers, and replaying it into the vision nodes reproduces its verdicts."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy

from conftest import REPO, spin_until
from woody_tools.graph import NodeProcess, entry_point

SAMPLE = REPO / "bags" / "sample" / "line.mcap"
CAMERA_TOPICS = ["/top_camera/depth/image_raw", "/top_camera/depth/camera_info", "/side_camera/image_raw"]


def recorded_verdicts():
    from woody_tools.mcap_io import decode, read_bag

    return [decode(t, d) for _, t, d, _ in read_bag(SAMPLE, topics=["/grading/verdicts"])]


def test_sample_bag_opens_with_rosbags_and_mcap():
    from mcap_ros2.reader import read_ros2_messages
    from rosbags.highlevel import AnyReader

    with AnyReader([SAMPLE]) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        depth = next(reader.messages(connections=[c for c in reader.connections
                                                  if c.topic == "/top_camera/depth/image_raw"]))
        image = reader.deserialize(depth[2], depth[0].msgtype)
    assert topics["/grading/verdicts"] == "woody_msgs/msg/FilletVerdict"
    assert (image.width, image.height, image.encoding) == (672, 376, "32FC1")
    verdicts = [m.ros_msg for m in read_ros2_messages(str(SAMPLE), topics=["/grading/verdicts"])]
    assert len(verdicts) == len(recorded_verdicts()) == 3


def test_replaying_the_sample_into_segmenter_and_grader_reproduces_its_verdicts(ros_node, ros_domain, tmp_path):
    from woody_msgs.msg import FilletVerdict

    expected = recorded_verdicts()
    received: list = []
    ros_node.create_subscription(FilletVerdict, "/grading/verdicts", received.append,
                                 QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))
    vision = {"use_sim_time": True, "lanes": 3}
    nodes = [NodeProcess("segmenter", vision, domain_id=ros_domain, log_dir=tmp_path),
             NodeProcess("grader", vision, domain_id=ros_domain, log_dir=tmp_path)]
    replay = NodeProcess("woody", None, domain_id=ros_domain, log_dir=tmp_path,
                         extra_args=["replay", str(SAMPLE), "--topics", *CAMERA_TOPICS])
    try:
        spin_until(ros_node, lambda: not replay.alive(), timeout=120.0)
        spin_until(ros_node, lambda: len(received) >= len(expected), timeout=5.0)
    finally:
        code = replay.stop()
        for node in nodes:
            node.stop()
    assert code == 0, replay.log_tail()
    logs = "\n".join(n.log_tail() for n in [replay, *nodes])
    assert len(received) == len(expected), logs

    def key(v):
        return (v.lane, v.header.stamp.sec, v.header.stamp.nanosec)

    for got, want in zip(sorted(received, key=key), sorted(expected, key=key)):
        assert (got.lane, got.classification, got.header.stamp) == (want.lane, want.classification, want.header.stamp)
        assert got.phi == pytest.approx(want.phi, rel=1e-6)
        assert got.side_measured == want.side_measured
        if want.side_measured:
            assert got.nmdm == pytest.approx(want.nmdm, rel=1e-6) and got.be == pytest.approx(want.be, rel=1e-6)
        else:
            assert math.isnan(got.nmdm)


def test_report_rebuilds_from_the_sample_bag(tmp_path):
    result = subprocess.run([entry_point("woody"), "report", str(SAMPLE), "--out", str(tmp_path)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    report = (tmp_path / "report.md").read_text()
    assert "accuracy" in report and (tmp_path / "phi_by_k_lane.png").stat().st_size > 1000
    rows = (tmp_path / "verdicts.csv").read_text().splitlines()
    assert len(rows) == 4 and rows[0].startswith("fillet_id,lane,mesh,k,speed_fpm,phi")


def test_bad_inputs_give_one_line_errors(tmp_path):
    truncated = tmp_path / "cut.mcap"
    truncated.write_bytes(SAMPLE.read_bytes()[: SAMPLE.stat().st_size // 3])
    for args in (["report", str(tmp_path / "missing.mcap")], ["replay", str(tmp_path / "missing.mcap")],
                 ["report", str(REPO / "README.md")]):
        result = subprocess.run([entry_point("woody"), *args], capture_output=True, text=True, timeout=60)
        assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1, (args, result.stderr)
        assert "Traceback" not in result.stderr
    result = subprocess.run([sys.executable, "-m", "woody_tools.cli", "report", str(truncated), "--out", str(tmp_path)],
                            capture_output=True, text=True, timeout=60)
    assert "Traceback" not in result.stderr and "cut.mcap" in result.stderr + result.stdout
