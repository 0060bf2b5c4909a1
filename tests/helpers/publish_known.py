"""Publish `known_messages` on their topics: message i of every topic each period.

--wait-for N: first wait until every publisher has N subscribers (the recorder).
/line/ground_truth (transient-local) message 0 goes out at once, before anyone
listens, to check that latched data is recorded. Prints "published <n>" at the
end and stays --linger seconds so reliable data is delivered.
"""

import argparse
import sys
import time
from pathlib import Path

import rclpy
from rclpy.node import Node

sys.path.insert(0, str(Path(__file__).resolve().parent))
from known_messages import TOPICS, known  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--count", type=int, default=20)
    parser.add_argument("--rate", type=float, default=20.0)
    parser.add_argument("--wait-for", type=int, default=1)
    parser.add_argument("--linger", type=float, default=1.0)
    parser.add_argument("--small-images", action="store_true")
    parser.add_argument("--wait-topics", nargs="+", help="topics whose subscribers to wait for (default all)")
    args = parser.parse_args()
    rclpy.init()
    node = Node("publish_known")
    pubs = {topic: node.create_publisher(cls, topic, qos) for topic, (cls, qos) in TOPICS.items()}
    pubs["/line/ground_truth"].publish(known("/line/ground_truth", 0))
    deadline = time.monotonic() + 30.0
    waited = [pubs[t] for t in (args.wait_topics or pubs)]
    while (any(p.get_subscription_count() < args.wait_for for p in waited)
           and time.monotonic() < deadline):
        time.sleep(0.02)
    time.sleep(0.3)
    msgs = {topic: [known(topic, i, args.small_images) for i in range(min(args.count, 50))] for topic in TOPICS}
    start = time.monotonic()
    print(f"start {time.time():.6f}", flush=True)
    for i in range(args.count):
        for topic, pub in pubs.items():
            if topic == "/line/ground_truth" and i == 0:
                continue
            msg = msgs[topic][i] if i < 50 else known(topic, i, args.small_images)
            pub.publish(msg)
        if i % 10 == 9:
            print(f"sent {i + 1} {time.time():.6f}", flush=True)
        time.sleep(max(0.0, start + (i + 1) / args.rate - time.monotonic()))
    print(f"published {args.count}", flush=True)
    time.sleep(args.linger)
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
