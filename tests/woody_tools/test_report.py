"""`woody report` through the real entry point: a bag cut short still gives a report saying where it ends;
unreadable input or an unwritable --out is one line and exit code 2."""

from __future__ import annotations

import subprocess

import pytest
from conftest import REPO

from woody_tools.processes import entry_point

pytestmark = pytest.mark.ros
"""Starts node entry points or `woody` as processes."""

SAMPLE = REPO / "bags" / "sample"


def report(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([entry_point("woody"), "report", *args], capture_output=True, text=True, timeout=120)


def test_a_bag_cut_short_is_reported_up_to_where_it_ends(tmp_path):
    data = (SAMPLE / "line.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:int(len(data) * 0.9)])
    result = report(str(cut), "--out", str(tmp_path / "out"))
    assert result.returncode == 0, result.stderr
    assert "truncated after" in result.stderr and "reporting its readable part" in result.stderr
    text = (tmp_path / "out" / "report.md").read_text()
    assert "the bag ends early: " in text and "truncated after" in text
    rows = (tmp_path / "out" / "verdicts.csv").read_text().splitlines()
    assert len(rows) == 1 + 3  # the three fillets the readable part holds


@pytest.mark.parametrize("args,message", [
    (["{tmp}/nothing.mcap"], "no such file"),
    (["{tmp}/bad.mcap"], "not an MCAP file"),
    ([str(SAMPLE / "verdicts.csv"), "--out", "/proc/woody"], "/proc/woody"),
    ([str(SAMPLE / "line.mcap"), "--out", "/proc/woody"], "/proc/woody"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, args, message):
    (tmp_path / "bad.mcap").write_text("not a bag")
    result = report(*[a.format(tmp=tmp_path) for a in args])
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("woody report: ") and message in lines[0], lines


def test_the_report_of_a_bag_has_one_picture_per_fillet_from_its_overlays(tmp_path):
    result = report(str(SAMPLE / "line.mcap"), "--out", str(tmp_path))
    assert result.returncode == 0, result.stderr
    fillets = (tmp_path / "verdicts.csv").read_text().splitlines()[1:]
    pictures = sorted(p.name for p in (tmp_path / "fillets").glob("*.png"))
    assert len(pictures) == len(fillets) == 3
    text = (tmp_path / "report.md").read_text()
    assert all(f"](fillets/{name})" in text for name in pictures)
