"""`BagWriter` at a file size limit (RLIMIT_FSIZE, the stand-in for a full disk): the file is cut back to its last
whole record, reads up to there, and `recover_bag` makes it a complete bag."""

from __future__ import annotations

import subprocess
import sys
import textwrap

from woody_bag.errors import BagError
from woody_bag.reader import read_bag
from woody_bag.recovery import recover_bag

LIMIT = 2_000_000

WRITE_UNTIL_FULL = textwrap.dedent(f"""
    import os, resource, signal, sys
    from woody_bag.writer import BagWriter
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, ({LIMIT}, {LIMIT}))
    writer = BagWriter(sys.argv[1], chunk_size=300_000, compression="none")
    writer.add_topic("/clock", "rosgraph_msgs/msg/Clock")
    data = bytes(4) + os.urandom(8)  # a CDR header and a Clock
    for i in range(10**6):
        try:
            writer.write("/clock", data, 10**9 + i)
        except OSError as exc:
            print(i, exc.errno)
            break
""")


def test_a_write_past_the_limit_leaves_whole_records_only(tmp_path):
    import errno

    bag = tmp_path / "full.mcap"
    result = subprocess.run([sys.executable, "-c", WRITE_UNTIL_FULL, str(bag)], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 0, result.stderr
    accepted, code = map(int, result.stdout.split())
    assert code == errno.EFBIG
    size = bag.stat().st_size
    assert 0 < size < LIMIT  # the kernel wrote up to the limit; the partial chunk's bytes were given back
    read = 0
    try:
        for _ in read_bag(bag):
            read += 1
    except BagError as exc:
        assert "truncated after" in str(exc)
    assert 0 < read <= accepted + 1  # the failing write's message may sit in the last whole chunk
    result = recover_bag(bag, tmp_path / "rescued.mcap")
    assert result["messages"] == read and result["error"].startswith(f"{bag}: truncated after {read} messages")
    assert sum(1 for _ in read_bag(tmp_path / "rescued.mcap")) == read


def test_a_closed_bag_carries_rosbag2s_metadata_and_type_hashes_and_a_recovered_copy_its_own(tmp_path):
    import yaml
    from fixtures.rosbag2_conformance import assert_rosbag2_conformant, file_order
    from rclpy.qos import QoSProfile

    from woody_bag.qos import qos_profiles_yaml
    from woody_bag.schemas import type_hash
    from woody_bag.writer import BagWriter

    bag = tmp_path / "line.mcap"
    with BagWriter(bag) as writer:
        writer.add_topic("/clock", "rosgraph_msgs/msg/Clock", qos_profiles_yaml([QoSProfile(depth=1)]))
        writer.add_topic("/unused", "std_msgs/msg/Empty")
        for i in range(5):
            writer.write("/clock", bytes(4) + bytes(8), 2_000_000_000 + i * 1000)
    messages = assert_rosbag2_conformant(bag)
    assert len(messages) == 5
    channels, _, metadata = file_order(bag)
    assert {c.topic: c.metadata["topic_type_hash"] for c in channels} == {
        "/clock": type_hash("rosgraph_msgs/msg/Clock"), "/unused": type_hash("std_msgs/msg/Empty")}
    listed = yaml.safe_load(metadata["rosbag2"]["serialized_metadata"])["topics_with_message_count"]
    assert {t["topic_metadata"]["name"]: t["message_count"] for t in listed} == {"/clock": 5, "/unused": 0}
    assert recover_bag(bag, tmp_path / "copy.mcap")["messages"] == 5
    assert len(assert_rosbag2_conformant(tmp_path / "copy.mcap")) == 5  # one rosbag2 record, of the copy
