"""woody_msgs round trips and camera-size images across processes over the project's Fast DDS profile."""

from __future__ import annotations

import os

import pytest
from conftest import REPO, spin_until
from msg_samples import samples, spawn_request
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy


def test_profile_is_the_projects():
    assert os.environ.get("FASTRTPS_DEFAULT_PROFILES_FILE") == str(REPO / "config" / "fastdds.xml")


def test_every_message_type_round_trips_between_processes(ros_node, spawn_helper):
    expected = samples()
    received: dict[str, object] = {}
    qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    for name, msg in expected.items():
        ros_node.create_subscription(type(msg), f"/samples/{name}", lambda m, n=name: received.setdefault(n, m), qos)
    publisher = spawn_helper("publish_samples")
    assert spin_until(ros_node, lambda: len(received) == len(expected), timeout=20.0), (
        f"received only {sorted(received)}; helper exit {publisher.poll()}")
    for name, msg in expected.items():
        assert received[name] == msg, name


def test_spawn_service_round_trips(ros_node, spawn_helper):
    from woody_msgs.srv import SpawnFillet

    spawn_helper("publish_samples")
    client = ros_node.create_client(SpawnFillet, "/spawn_fillet")
    assert spin_until(ros_node, client.service_is_ready, timeout=20.0)
    future = client.call_async(spawn_request())
    assert spin_until(ros_node, future.done, timeout=10.0)
    response = future.result()
    assert response.success and response.fillet_id == 99
    assert response.message == "seed0002 k=60.0 lane=1 v=0.66 m=3.141592653589793"


@pytest.mark.parametrize("width,height,rate,seconds", [(960, 696, 200.0, 3.0)])
def test_side_camera_images_cross_processes_at_200_hz(ros_node, spawn_helper, width, height, rate, seconds):
    from sensor_msgs.msg import Image

    count = int(rate * seconds)
    frames: set[int] = set()

    def on_image(msg: Image) -> None:
        assert msg.width == width and msg.height == height and len(msg.data) == width * height * 3
        frames.add(int(msg.header.frame_id))

    ros_node.create_subscription(Image, "/blast/image_raw", on_image,
                                 QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))
    blaster = spawn_helper("image_blaster", "--count", str(count), "--rate", str(rate),
                           "--width", str(width), "--height", str(height))
    spin_until(ros_node, lambda: len(frames) >= count or blaster.poll() is not None, timeout=40.0)
    spin_until(ros_node, lambda: len(frames) >= count, timeout=2.0)
    assert len(frames) >= 0.99 * count, f"received {len(frames)}/{count} images"
