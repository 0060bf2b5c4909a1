"""Publish N rgb8 images of WxH at a fixed rate once a subscriber is matched (transport test)."""

import argparse
import time

import numpy as np
import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--count", type=int, default=600)
    parser.add_argument("--rate", type=float, default=200.0)
    parser.add_argument("--width", type=int, default=960)
    parser.add_argument("--height", type=int, default=696)
    args = parser.parse_args()
    rclpy.init()
    node = Node("image_blaster")
    qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
    publisher = node.create_publisher(Image, "/blast/image_raw", qos)
    deadline = time.monotonic() + 30.0
    while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(0.5)
    pixels = np.random.default_rng(0).integers(0, 255, (args.height, args.width, 3), dtype=np.uint8)
    msg = Image(height=args.height, width=args.width, encoding="rgb8", step=args.width * 3)
    msg.data = pixels.tobytes()
    period = 1.0 / args.rate
    start = time.monotonic()
    for i in range(args.count):
        msg.header.frame_id = str(i)
        publisher.publish(msg)
        next_time = start + (i + 1) * period
        time.sleep(max(0.0, next_time - time.monotonic()))
    elapsed = time.monotonic() - start
    print(f"published {args.count} in {elapsed:.2f} s", flush=True)
    time.sleep(1.0)
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
