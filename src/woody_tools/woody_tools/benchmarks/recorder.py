"""Recorder throughput: the real `recorder` entry point against camera-sized image streams.

Publishes /side_camera/image_raw (960x696 rgb8) at --side-rate Hz and
/top_camera/color/image_raw (672x376 rgb8) + /top_camera/depth/image_raw
(672x376 32FC1) at --top-rate Hz for --seconds, on a private domain, records
them, then prints published vs recorded counts, MB/s and the recorder's CPU.
Frames are a cycle of 16 synthetic scenes with sensor noise (sigma --noise),
i.e. about as compressible as rendered camera images with noise.
Not a test (too slow for the suite): `python -m woody_tools.benchmarks.recorder`.
"""

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image

from woody_bag.summary import bag_summary
from woody_tools.cpu_usage import cpu_seconds
from woody_tools.processes import NodeProcess, lease_domain


def frames(width, height, noise, depth=False, n=16):
    rng = np.random.default_rng(1)
    yy, xx = np.mgrid[0:height, 0:width]
    out = []
    for k in range(n):
        if depth:
            img = np.full((height, width), 0.9, np.float32)
            for cx in (0.2, 0.5, 0.8):
                img[((xx - cx * width - 3 * k) / 60) ** 2 + ((yy - height / 2) / 35) ** 2 < 1] = 0.87
            img += rng.normal(0, 0.001, img.shape).astype(np.float32)
        else:
            img = np.zeros((height, width, 3), np.int16)
            img[...] = (60, 60, 70)
            for cx in (0.2, 0.5, 0.8):
                img[((xx - cx * width - 3 * k) / 90) ** 2 + ((yy - height / 2) / 50) ** 2 < 1] = (230, 170, 160)
            if noise:
                img = img + rng.normal(0, noise, img.shape)
            img = np.clip(img, 0, 255).astype(np.uint8)
        out.append(img.tobytes())
    return out


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--side-rate", type=float, default=200.0)
    parser.add_argument("--top-rate", type=float, default=30.0)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--noise", type=float, default=2.0)
    parser.add_argument("--compression", default="zstd")
    parser.add_argument("--side-size", default="960x696", help="WxH of the side camera frames")
    args = parser.parse_args()
    side_w, side_h = (int(v) for v in args.side_size.split("x"))
    tmp = Path(tempfile.mkdtemp(prefix="woody-bench-"))
    lease = lease_domain({k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"})
    os.environ["ROS_DOMAIN_ID"] = str(lease.domain_id)
    bag = tmp / "bench.mcap"
    recorder = NodeProcess("recorder", {"output": str(bag), "discovery_period": 0.2,
                                        "compression": args.compression},
                           domain_id=lease.domain_id, log_dir=tmp)
    rclpy.init()
    node = Node("bench_publisher")
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    streams = [
        ("/side_camera/image_raw", args.side_rate, side_w, side_h, "rgb8", frames(side_w, side_h, args.noise)),
        ("/top_camera/color/image_raw", args.top_rate, 672, 376, "rgb8", frames(672, 376, args.noise)),
        ("/top_camera/depth/image_raw", args.top_rate, 672, 376, "32FC1", frames(672, 376, 0, depth=True)),
    ]
    pubs = [(node.create_publisher(Image, topic, qos), rate, w, h, enc, data)
            for topic, rate, w, h, enc, data in streams]
    deadline = time.monotonic() + 20
    while any(p.get_subscription_count() == 0 for p, *_ in pubs) and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)
    msgs = []
    for _pub, _rate, w, h, enc, data in pubs:
        bpp = 4 if enc == "32FC1" else 3
        msgs.append([Image(height=h, width=w, encoding=enc, step=w * bpp, data=d) for d in data])
    cpu0 = cpu_seconds(recorder.process.pid)
    start = time.monotonic()
    sent = _publish_streams(pubs, msgs, args.seconds)
    elapsed = time.monotonic() - start
    cpu = cpu_seconds(recorder.process.pid) - cpu0
    time.sleep(1.0)
    code = recorder.stop(30)
    print(f"recorder exit {code}; {elapsed:.1f} s; recorder CPU {cpu / elapsed:.2f} cores; "
          f"bag {bag.stat().st_size / 1e6:.0f} MB")
    _print_recorded(bag_summary(bag), streams, sent, elapsed)
    print(recorder.log_tail(1))
    node.destroy_node()
    rclpy.try_shutdown()
    bag.unlink()


def _publish_streams(pubs, msgs, seconds: float) -> list[int]:
    """Publish every stream at its rate for ``seconds`` (cycling its frames); the count sent per stream."""
    sent = [0] * len(pubs)
    next_t = [0.0] * len(pubs)
    start = time.monotonic()
    while (now := time.monotonic() - start) < seconds:
        k = min(range(len(pubs)), key=lambda j: next_t[j])
        if next_t[k] > now:
            time.sleep(next_t[k] - now)
        pub = pubs[k][0]
        pub.publish(msgs[k][sent[k] % 16])
        sent[k] += 1
        next_t[k] = sent[k] / pubs[k][1]
    return sent


def _print_recorded(summary: dict, streams, sent: list[int], elapsed: float) -> None:
    """Sent vs recorded per stream and the sustained message and payload rates."""
    total_bytes = 0
    for (topic, _rate, _w, _h, _enc, data), n in zip(streams, sent):
        got = summary["topics"].get(topic, {}).get("count", 0)
        total_bytes += got * len(data[0])
        print(f"  {topic}: sent {n} ({n / elapsed:.0f}/s), recorded {got} ({100 * got / max(n, 1):.1f} %)")
    total = sum(t["count"] for t in summary["topics"].values())
    print(f"  sustained: {total / elapsed:.0f} msgs/s, {total_bytes / elapsed / 1e6:.0f} MB/s of payload")


if __name__ == "__main__":
    main()
