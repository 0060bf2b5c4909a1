"""The real entry points as separate processes: line_sim's topics, and the whole grading graph."""

from __future__ import annotations

import re

import numpy as np
import pytest
from conftest import spin_until
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from woody_common.stamps import stamp_to_seconds
from woody_tools.processes import NodeProcess

pytestmark = pytest.mark.ros
"""Starts node entry points or `woody` as processes."""


def test_line_sim_publishes_every_topic_at_its_rate(ros_node, ros_domain, tmp_path):
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import CameraInfo, Image

    from woody_msgs.msg import FilletSpawn

    duration = 3.0
    topics = {
        "/top_camera/color/image_raw": Image, "/top_camera/depth/image_raw": Image,
        "/top_camera/color/camera_info": CameraInfo, "/top_camera/depth/camera_info": CameraInfo,
        "/side_camera/image_raw": Image, "/side_camera/camera_info": CameraInfo,
    }
    received: dict[str, list] = {name: [] for name in [*topics, "/clock", "/line/ground_truth"]}
    reliable = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
    for name, msg_type in topics.items():
        ros_node.create_subscription(msg_type, name, lambda m, n=name: received[n].append(m), reliable)
    ros_node.create_subscription(Clock, "/clock", lambda m: received["/clock"].append(stamp_to_seconds(m.clock)), 100)
    ros_node.create_subscription(FilletSpawn, "/line/ground_truth", received["/line/ground_truth"].append,
                                 QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                            durability=DurabilityPolicy.TRANSIENT_LOCAL))
    # Paced to the wall clock: unpaced, the line runs faster than real time (two physics processes), and this
    # test's one Python thread, taking 2 MB side frames at 60 Hz, then falls behind the cameras' 10-deep queues.
    sim = NodeProcess("line_sim", {"duration_s": duration, "wait_for_subscribers": 1, "side_rate_hz": 60.0,
                                   "side_idle_rate_hz": 60.0, "realtime": True},
                      domain_id=ros_domain, log_dir=tmp_path)
    try:
        spin_until(ros_node, lambda: not sim.alive(), timeout=120.0)
        spin_until(ros_node, lambda: False, timeout=1.0)
    finally:
        assert sim.stop() == 0, sim.log_tail()

    def stamps(name):
        return np.array([stamp_to_seconds(m.header.stamp) for m in received[name]])

    top, side = stamps("/top_camera/depth/image_raw"), stamps("/side_camera/image_raw")
    assert abs(len(top) - 30 * duration) <= 3, len(top)
    assert abs(len(side) - 60 * duration) <= 3, len(side)
    assert np.allclose(np.diff(top), 1 / 30, atol=0.003) and np.allclose(np.diff(side), 1 / 60, atol=0.003)
    assert len(stamps("/top_camera/color/image_raw")) == len(top) == len(stamps("/top_camera/depth/camera_info"))
    clock = np.array(received["/clock"])
    assert len(clock) > 100 and np.all(np.diff(clock) > 0) and clock[-1] == pytest.approx(duration, abs=0.01)
    depth, color, info = (received[n][0] for n in ("/top_camera/depth/image_raw", "/top_camera/color/image_raw",
                                                   "/top_camera/depth/camera_info"))
    assert (depth.width, depth.height, depth.encoding) == (672, 376, "32FC1")
    assert (color.width, color.height, color.encoding) == (672, 376, "rgb8")
    assert received["/side_camera/image_raw"][0].width == 960 and received["/side_camera/image_raw"][0].height == 696
    assert info.k[0] > 0 and info.header.frame_id == depth.header.frame_id == "top_camera_optical_frame"
    belt = np.frombuffer(bytes(depth.data), np.float32).reshape(376, 672)[188, 336]
    assert belt == pytest.approx(0.75, abs=0.002)  # the belt plane, metres from the camera
    spawns = received["/line/ground_truth"]
    assert len(spawns) >= 3 and len({s.fillet_id for s in spawns}) == len(spawns)
    assert {s.lane for s in spawns} == {0, 1, 2} and all(s.stiffness in (0.0, 100.0) for s in spawns)


def test_graph_gives_exactly_one_verdict_per_fillet(ros_node, ros_domain, tmp_path):
    from woody_msgs.msg import FilletSpawn, FilletVerdict, GateCommand, SideMetrics

    verdicts: list = []
    sides: list = []
    commands: list = []
    spawns: list = []
    reliable = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    ros_node.create_subscription(FilletVerdict, "/grading/verdicts", verdicts.append, reliable)
    ros_node.create_subscription(SideMetrics, "/grading/side_metrics", sides.append, reliable)
    ros_node.create_subscription(GateCommand, "/reject_gate/commands", commands.append, reliable)
    ros_node.create_subscription(FilletSpawn, "/line/ground_truth", spawns.append,
                                 QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                            durability=DurabilityPolicy.TRANSIENT_LOCAL))
    vision = {"use_sim_time": True, "lanes": 3}
    nodes = [NodeProcess("segmenter", vision, domain_id=ros_domain, log_dir=tmp_path),
             NodeProcess("grader", vision, domain_id=ros_domain, log_dir=tmp_path),
             NodeProcess("reject_gate", {"use_sim_time": True}, domain_id=ros_domain, log_dir=tmp_path)]
    # The line starts once the segmenter's tracks publisher and the grader's subscription are both up and have had
    # a moment to match (the link is volatile: tracks sent before it are lost, and the first fillets with them).
    spin_until(ros_node, lambda: ros_node.count_subscribers("/vision/tracks") >= 1
               and ros_node.count_publishers("/vision/tracks") >= 1, timeout=60.0)
    spin_until(ros_node, lambda: False, timeout=1.0)
    nodes.append(NodeProcess("line_sim", {"fillets": 6, "duration_s": 5.5, "wait_for_subscribers": 1,
                                          "max_lead_s": 0.1}, domain_id=ros_domain, log_dir=tmp_path))
    try:
        spin_until(ros_node, lambda: not nodes[-1].alive() or not all(n.alive() for n in nodes[:3]), timeout=240.0)
        spin_until(ros_node, lambda: False, timeout=2.0)
        assert all(n.alive() for n in nodes[:3]), "\n".join(n.log_tail() for n in nodes)
    finally:
        for node in nodes:
            node.stop()
    assert len(spawns) == 6
    logs = "\n".join(f"--- {n.name}\n{n.log_tail(40)}" for n in nodes)
    ids = [v.fillet_id for v in verdicts]
    assert len(ids) == len(set(ids)), f"a fillet got two verdicts: {ids}"
    assert len(verdicts) == 6, f"{len(verdicts)} verdicts for 6 fillets\n{logs}"
    assert sorted(v.lane for v in verdicts) == sorted(s.lane for s in spawns)
    scored = [v for v in verdicts if v.classification != FilletVerdict.CLASS_UNSCORED]
    assert len(scored) >= 5, f"{[v.unscored_reason for v in verdicts]}\n{logs}"
    assert all(np.isfinite(v.phi) and v.phi >= 0 for v in scored)
    watched = sorted(v.fillet_id for v in verdicts if v.lane == 1)
    assert sorted(m.fillet_id for m in sides) == watched, "one side result per watched-lane verdict"
    assert all(m.lane == 1 for m in sides) and any(m.measured and np.isfinite(m.nmdm) for m in sides), logs
    woody = [v for v in verdicts if v.classification == FilletVerdict.CLASS_WOODY]
    assert len(commands) == len(woody) and {c.fillet_id for c in commands} == {v.fillet_id for v in woody}


def test_line_sim_publishes_what_a_structured_light_camera_would(ros_node, ros_domain, tmp_path):
    """16UC1 millimetre depth with 0 where nothing was measured, noisy colour, a few dropped frames at most."""
    from scipy.spatial.transform import Rotation
    from sensor_msgs.msg import Image
    from tf2_msgs.msg import TFMessage

    frames: dict[str, list] = {"depth": [], "color": []}
    best_effort = QoSProfile(depth=50, reliability=ReliabilityPolicy.BEST_EFFORT)
    for kind in frames:
        ros_node.create_subscription(Image, f"/top_camera/{kind}/image_raw", frames[kind].append, best_effort)
    static: list = []
    ros_node.create_subscription(TFMessage, "/tf_static", static.append,
                                 QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    sim = NodeProcess("line_sim", {"duration_s": 1.0, "wait_for_subscribers": 1, "side_rate_hz": 0.0,
                                   "sensor": "structured_light"}, domain_id=ros_domain, log_dir=tmp_path)
    try:
        spin_until(ros_node, lambda: not sim.alive(), timeout=120.0)
        spin_until(ros_node, lambda: False, timeout=1.0)
    finally:
        assert sim.stop() == 0, sim.log_tail()
    assert 25 <= len(frames["depth"]) <= 31 and len(frames["color"]) == len(frames["depth"])
    (tf,) = static  # the camera 0.75 m over the belt, its optical axis (z) pointing down, image rows downstream
    fixed = {t.child_frame_id: t for t in tf.transforms}
    assert set(fixed) == {"roller", "top_camera_optical_frame", "side_camera_optical_frame"}
    top = fixed["top_camera_optical_frame"]
    assert top.header.frame_id == "world" and top.transform.translation.z == pytest.approx(0.75)
    q = top.transform.rotation
    axes = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    assert np.allclose(axes[:, 2], [0, 0, -1]) and np.allclose(axes[:, 1], [1, 0, 0])
    depth = frames["depth"][0]
    assert depth.encoding == "16UC1" and depth.step == 672 * 2
    mm = np.frombuffer(bytes(depth.data), np.uint16).reshape(376, 672)
    assert 0.001 < (mm == 0).mean() < 0.1  # holes and edge bands
    assert abs(int(np.median(mm[150:220, 300:370])) - 750) <= 3  # the belt, in millimetres
    rgb = np.frombuffer(bytes(frames["color"][0].data), np.uint8).reshape(376, 672, 3)
    assert np.std(rgb[150:220, 300:370].astype(float)) > 1.0  # pixel noise on the uniform belt


def test_spawn_service_spawns_or_explains(ros_node, ros_domain, tmp_path):
    from woody_msgs.srv import SpawnFillet

    bad_mesh = tmp_path / "empty.obj"
    bad_mesh.write_text("")
    sim = NodeProcess("line_sim", {"realtime": True}, domain_id=ros_domain, log_dir=tmp_path)
    client = ros_node.create_client(SpawnFillet, "/spawn_fillet")
    try:
        assert spin_until(ros_node, client.service_is_ready, timeout=60.0), sim.log_tail()
        answers = []
        for request in (SpawnFillet.Request(mesh="seed0001", stiffness=40.0, lane=2),
                        SpawnFillet.Request(mesh=str(bad_mesh), stiffness=0.0, lane=0),
                        SpawnFillet.Request(mesh="seed0001", stiffness=-5.0, lane=0),
                        SpawnFillet.Request(mesh="seed0001", stiffness=0.0, lane=9)):
            future = client.call_async(request)
            assert spin_until(ros_node, future.done, timeout=20.0)
            answers.append(future.result())
    finally:
        sim.stop()
    assert answers[0].success and answers[0].message.startswith("spawned")
    assert not answers[1].success and "empty.obj" in answers[1].message
    assert not answers[2].success and "stiffness" in answers[2].message
    assert not answers[3].success and "lane" in answers[3].message


def test_line_sim_holds_its_first_step_until_the_recorder_listens_to_every_topic(ros_domain, tmp_path):
    """With ``wait_for_recorder`` the bag starts with the first step on every topic: the first clock, the first frame of
    each camera and the latched ground truth (the recorder finds topics every 0.5 s, so without the wait it
    would join after the line had started)."""
    from woody_bag.reader import read_bag
    from woody_bag.schemas import decode

    recorder = NodeProcess("recorder", {"output": str(tmp_path / "line.mcap"), "use_sim_time": True},
                           domain_id=ros_domain, log_dir=tmp_path)
    sim = NodeProcess("line_sim", {"duration_s": 1.0, "realtime": True, "side_idle_rate_hz": 60.0,
                                   "wait_for_recorder": "recorder"}, domain_id=ros_domain, log_dir=tmp_path)
    try:
        assert sim.process.wait(120) == 0, sim.log_tail()
    finally:
        sim.stop()
        assert recorder.stop() == 0, recorder.log_tail()
    assert "recorder on every topic" in sim.log_path.read_text()
    first: dict[str, float] = {}
    frames = 0
    for message in read_bag(tmp_path / "line.mcap"):
        decoded = decode(message.type_name, message.data)
        stamp = decoded.clock if message.topic == "/clock" else getattr(decoded, "header", None)
        stamp = stamp.stamp if hasattr(stamp, "stamp") else stamp
        if stamp is not None:
            first.setdefault(message.topic, stamp_to_seconds(stamp))
        frames += message.topic == "/top_camera/depth/image_raw"
    step = first["/clock"]  # the first physics step's time: the line's first frames go out with it
    assert 0.0 < step < 0.005 and first["/top_camera/depth/image_raw"] == first["/side_camera/image_raw"] == step
    assert "/line/ground_truth" in first and frames == 31  # dt, then every 1/30 s to 1.0 s: none before the recorder


def test_line_sim_takes_a_coarser_physics_step_and_chain_when_asked(ros_domain, tmp_path):
    """The physics settings docs/physics.md measures are parameters: the step rate, solver iterations, slices."""
    sim = NodeProcess("line_sim", {"duration_s": 0.5, "physics_rate_hz": 360.0, "solver_iterations": 10,
                                   "segments": 30, "side_rate_hz": 0.0}, domain_id=ros_domain, log_dir=tmp_path)
    try:
        assert sim.process.wait(120) == 0, sim.log_tail()
    finally:
        sim.stop()
    log = sim.log_path.read_text()
    assert "physics dt=2.78 ms, 30 segments, 10 solver iterations" in log


def test_line_sim_recycles_its_physics_workers_when_asked(ros_domain, tmp_path):
    """With physics_recycle_fillets every fillet is simulated in a worker, and a worker that has taken that many is
    replaced by a fresh process while the line runs (a shift keeps its memory flat, docs/physics.md)."""
    sim = NodeProcess("line_sim", {"duration_s": 2.5, "physics_recycle_fillets": 2, "side_rate_hz": 0.0},
                      domain_id=ros_domain, log_dir=tmp_path)
    try:
        assert sim.process.wait(180) == 0, sim.log_tail()
    finally:
        sim.stop()
    started = re.search(r"physics workers: (\d+) started, each replaced after 2 fillets", sim.log_path.read_text())
    assert started and int(started.group(1)) >= 2, sim.log_tail()  # 9 fillets: when a successor is up is timing
