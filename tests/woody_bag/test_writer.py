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
