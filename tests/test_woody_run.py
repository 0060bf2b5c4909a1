"""`woody run` end to end: bag, verdict table and report; a node that dies stops the run and the bag survives."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import time

from woody_tools.graph import entry_point


def _bag_messages(path):
    from woody_tools.mcap_io import bag_summary

    return bag_summary(path)


def test_woody_run_leaves_bag_table_and_report(tmp_path):
    """Run in a namespace, as one of several lines in a domain would: everything lives under it."""
    out = tmp_path / "run"
    result = subprocess.run([entry_point("woody"), "run", "--fillets", "3", "--k", "0", "100", "--seed", "3",
                             "--out", str(out), "--namespace", "line2"], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    rows = list(csv.DictReader((out / "verdicts.csv").open()))
    assert len(rows) == 3 and {r["lane"] for r in rows} == {"0", "1", "2"}
    assert all(r["verdict"] in ("normal", "woody") and r["truth"] in ("normal", "woody") for r in rows)
    assert list(rows[0])[:12] == ["fillet_id", "lane", "mesh", "k", "speed_fpm", "phi", "hu_term", "solidity_term",
                                  "nmdm", "mdm", "be", "verdict"]
    report = (out / "report.md").read_text()
    assert "accuracy" in report and "Φ" in report
    for png in ("phi_by_k_lane.png", "nmdm_by_k.png", "confusion.png"):
        assert (out / png).stat().st_size > 1000
    summary = _bag_messages(out / "line.mcap")
    assert summary["complete"], summary
    counts = {topic: info["count"] for topic, info in summary["topics"].items()}
    assert all(topic.startswith("/line2/") for topic in counts), sorted(counts)
    assert counts["/line2/grading/verdicts"] == 3 and counts["/line2/line/ground_truth"] == 3
    assert counts["/line2/top_camera/depth/image_raw"] > 30 and counts["/line2/clock"] > 100
    assert "fillet_id" in result.stdout and str(out / "line.mcap") in result.stdout
    report = subprocess.run([entry_point("woody"), "report", str(out / "line.mcap"), "--out", str(tmp_path / "again")],
                            capture_output=True, text=True, timeout=120)
    assert report.returncode == 0, report.stderr  # the namespaced bag's verdicts and ground truth are found
    assert len((tmp_path / "again" / "verdicts.csv").read_text().splitlines()) == 4


def test_a_dying_node_stops_the_run_and_the_bag_is_finalised(tmp_path):
    out = tmp_path / "run"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    run = subprocess.Popen([entry_point("woody"), "run", "--fillets", "30", "--out", str(out)],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    log = out / "logs" / "segmenter.log"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and "calibration received" not in (log.read_text() if log.exists() else ""):
        time.sleep(0.2)
    time.sleep(2.0)
    pids = subprocess.run(["pgrep", "-f", "bin/segmenter --ros-args"], capture_output=True, text=True).stdout.split()
    mine = [p for p in pids if str(out) in _parent_cmdline(p)]
    assert mine, f"segmenter of this run not found among {pids}"
    os.kill(int(mine[0]), signal.SIGKILL)
    stdout, stderr = run.communicate(timeout=120)
    assert run.returncode == 1
    assert "node 'segmenter' exited" in stderr
    summary = _bag_messages(out / "line.mcap")
    assert summary["complete"] and summary["topics"]["/top_camera/depth/image_raw"]["count"] > 0


def _parent_cmdline(pid: str) -> str:
    ppid = open(f"/proc/{pid}/stat").read().split(")")[1].split()[1]
    return open(f"/proc/{ppid}/cmdline", "rb").read().replace(b"\0", b" ").decode(errors="replace")
