"""Verdict latency across processes: deciding frame published here → verdict received here.

Starts the real segmenter and grader entry points on a private domain, plays a
synthetic multi-lane top-down stream (woody_vision.synthetic) at 30 Hz with
/clock and camera_info, and times every scored verdict against the wall time the
frame it was decided on was published: the latest frame published before the
verdict arrived, of those at or after the fillet's crossing (the verdict's stamp).
The grader decides on the frame that confirms the measuring point, a frame or two
after the crossing, well within a frame interval of it; were it more than a frame
behind, the figure would read low.
"""

from __future__ import annotations

import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from woody_common import topics
from woody_common.stamps import nanoseconds_to_stamp, stamp_to_nanoseconds
from woody_tools.processes import NodeProcess, lease_domain, wait_for

FRAME_RATE_HZ = 30.0
SCENE_LOOP_S = 8.0


def measure_verdict_latency(seconds: float = 10.0, lanes: int = 3, seed: int = 3) -> dict:
    """p50/p95 verdict latency (ms) and the verdict count over ``seconds`` of synthetic line."""
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import CameraInfo, Image

    from woody_vision.synthetic import TopScene, lane_streams

    loop_s = min(seconds, SCENE_LOOP_S)  # the scene repeats so drawing it stays cheap however long the run
    scene = TopScene(lane_streams(lanes, per_lane=max(2, int(loop_s / 0.9)), pitch_m=0.45, seed=seed,
                                  touching_probability=0.0))
    published: dict[int, float] = {}
    latencies: list[float] = []
    with lease_domain() as lease, tempfile.TemporaryDirectory() as logs:
        params = {"use_sim_time": True, "lanes": lanes}
        nodes = [NodeProcess("segmenter", params, domain_id=lease.domain_id, log_dir=Path(logs)),
                 NodeProcess("grader", dict(params, use_side_view=False), domain_id=lease.domain_id,
                             log_dir=Path(logs))]
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=lease.domain_id)
        node = rclpy.create_node("bench_latency", context=context)
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        clock_pub = node.create_publisher(Clock, "/clock", 10)
        depth_pub = node.create_publisher(Image, topics.TOP_DEPTH_IMAGE, qos)
        info_pub = node.create_publisher(CameraInfo, topics.TOP_DEPTH_INFO, qos)

        listener, listen, thread = _start_listener(context, published, latencies)
        try:
            _wait_for_vision(executor, depth_pub, info_pub)
            _publish_frames(scene, seconds, loop_s, (clock_pub, info_pub, depth_pub), published)
            time.sleep(1.0)
        finally:
            listen.shutdown()
            thread.join(timeout=5.0)
            listener.destroy_node()
            for process in nodes:
                process.stop()
            node.destroy_node()
            rclpy.try_shutdown(context=context)
    if not latencies:
        raise RuntimeError("no verdict was received; see the segmenter/grader logs")
    values = np.array(latencies)
    return {"count": int(values.size), "p50_ms": float(np.percentile(values, 50)),
            "p95_ms": float(np.percentile(values, 95))}


def _start_listener(context, published: dict[int, float], latencies: list[float]):
    """A node on its own executor thread taking each verdict's latency from when its deciding frame went out."""
    import rclpy
    from rclpy.qos import QoSProfile

    from woody_msgs.msg import FilletVerdict

    def on_verdict(msg: FilletVerdict) -> None:
        if msg.classification == FilletVerdict.CLASS_UNSCORED:
            return  # decided when the fillet was overdue or its track ended, frames after any frame of it
        now, crossing = time.monotonic(), stamp_to_nanoseconds(msg.header.stamp)
        sent = [when for stamp, when in list(published.items()) if stamp >= crossing and when <= now]
        if sent:
            latencies.append((now - max(sent)) * 1e3)

    # Verdicts are timestamped by their own executor thread, so drawing the next frame never delays them.
    listener = rclpy.create_node("bench_latency_listener", context=context)
    listener.create_subscription(FilletVerdict, topics.VERDICTS, on_verdict, QoSProfile(depth=100))
    listen = rclpy.executors.SingleThreadedExecutor(context=context)
    listen.add_node(listener)
    thread = threading.Thread(target=listen.spin, daemon=True)
    thread.start()
    return listener, listen, thread


def _wait_for_vision(executor, depth_pub, info_pub) -> None:
    """Until the segmenter subscribes to the depth image and both nodes to camera_info (RuntimeError after 30 s)."""
    ready = wait_for(lambda: (executor.spin_once(timeout_sec=0.05) or True)
                     and depth_pub.get_subscription_count() >= 1 and info_pub.get_subscription_count() >= 2,
                     timeout=30.0)
    if not ready:
        raise RuntimeError("segmenter/grader did not subscribe within 30 s")


def _publish_frames(scene, seconds: float, loop_s: float, publishers, published: dict[int, float]) -> None:
    """Publish /clock, camera_info and the depth image of each frame at the frame rate; note when each went out."""
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import CameraInfo
    from std_msgs.msg import Header

    from woody_common.images import serialized_image

    clock_pub, info_pub, depth_pub = publishers
    info = CameraInfo(width=scene.width, height=scene.height, distortion_model="plumb_bob")
    info.k = list(scene.k)
    start = time.monotonic()
    for i in range(int(seconds * FRAME_RATE_HZ)):
        t = i / FRAME_RATE_HZ
        _, depth = scene.render(t % loop_s)
        key = int(round(t * 1e9))
        clock = Clock()
        clock.clock = nanoseconds_to_stamp(key)
        clock_pub.publish(clock)
        info.header.stamp = clock.clock
        info_pub.publish(info)
        image = serialized_image(np.asarray(depth, np.float32), "32FC1", Header(stamp=clock.clock))
        published[key] = time.monotonic()
        depth_pub.publish(image)
        time.sleep(max(0.0, start + (i + 1) / FRAME_RATE_HZ - time.monotonic()))
