"""`woody bag info` and `woody bag recover` on bags cut short, through the real `woody` entry point.

A bag cut anywhere (what a SIGKILLed recorder leaves) is recovered into a complete,
indexed MCAP that `rosbags` and `mcap` open, holding every message of its complete
chunks; the run settings travel along. Bad input: one line, exit 2.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
from test_recorder import _bag_of_known

from woody_bag.errors import BagError
from woody_bag.reader import read_bag
from woody_bag.summary import bag_summary
from woody_tools.processes import entry_point

pytestmark = pytest.mark.ros
"""Starts node entry points or `woody` as processes."""


def woody(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([entry_point("woody"), *args], capture_output=True, text=True, timeout=120)


def cut_bag(tmp_path: Path, fraction: float) -> tuple[Path, list]:
    full = tmp_path / "full.mcap"
    written = _bag_of_known(full, chunk_size=8000, metadata={"run_settings": '{"lanes": 3}'})
    data = full.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:int(len(data) * fraction)])
    return cut, written


@pytest.mark.parametrize("fraction", [0.3, 0.55])
def test_recover_rewrites_every_complete_chunk_into_a_bag_all_readers_open(tmp_path, fraction):
    from mcap.reader import make_reader
    from rosbags.highlevel import AnyReader

    cut, written = cut_bag(tmp_path, fraction)
    readable = []
    with pytest.raises(BagError):
        for topic, _type, data, _t in read_bag(cut):
            readable.append((topic, data))
    out = tmp_path / "fixed.mcap"
    result = woody("bag", "recover", str(cut), str(out))
    assert result.returncode == 0, result.stderr
    assert f"recovered {len(readable)} messages" in result.stdout and "truncated after" in result.stdout

    summary = bag_summary(out)
    assert summary["complete"] and summary["message_count"] == len(readable) > 0
    assert summary["metadata"]["woody"]["run_settings"] == '{"lanes": 3}'
    assert "truncated after" in summary["metadata"]["woody.recover"]["source_end"]
    with AnyReader([out]) as reader:
        assert sum(1 for _ in reader.messages()) == len(readable)
    with open(out, "rb") as handle:
        mcap_reader = make_reader(handle)
        assert mcap_reader.get_summary().chunk_indexes  # indexed
        got = [(channel.topic, message.data) for _, channel, message in mcap_reader.iter_messages(log_time_order=False)]
    assert got == readable


def test_info_names_where_a_cut_bag_ends(tmp_path):
    cut, _ = cut_bag(tmp_path, 0.5)
    result = woody("bag", "info", str(cut))
    assert result.returncode == 0, result.stderr
    assert "NOT FINALISED" in result.stdout and "truncated after" in result.stdout and "/clock" in result.stdout
    assert "run_settings" in result.stdout
    # the same phrase as the terminal and report.md: a cut bag never wrote its losses record
    assert result.stdout.splitlines()[1].endswith("messages, losses not recorded")


@pytest.mark.parametrize("make,args,message", [
    (None, ["info", "{tmp}/nothing.mcap"], "no such file"),
    (b"hello, not a bag", ["info", "{tmp}/bad.mcap"], "not an MCAP file"),
    (b"hello, not a bag", ["recover", "{tmp}/bad.mcap", "{tmp}/out.mcap"], "not an MCAP file"),
    ("cut", ["recover", "{tmp}/cut.mcap", "{tmp}/cut.mcap"], "must differ from the input"),
    ("cut", ["recover", "{tmp}/cut.mcap", "{tmp}/full.mcap"], "already exists"),
    ("cut", ["recover", "{tmp}/cut.mcap", "/proc/woody/out.mcap"], "cannot create bag"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, make, args, message):
    if make == "cut":
        cut_bag(tmp_path, 0.5)
    elif make is not None:
        (tmp_path / "bad.mcap").write_bytes(make)
    result = woody("bag", *[a.format(tmp=tmp_path) for a in args])
    assert result.returncode == 2
    assert message in result.stderr and len(result.stderr.strip().splitlines()) == 1, result.stderr


def test_recover_force_overwrites(tmp_path):
    cut, _ = cut_bag(tmp_path, 0.5)
    assert woody("bag", "recover", str(cut), str(tmp_path / "full.mcap"), "--force").returncode == 0
    assert bag_summary(tmp_path / "full.mcap")["complete"]
