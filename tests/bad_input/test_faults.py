"""`woody run` owns its processes however it ends, and tells the truth about what the line did.

Every test starts the real `woody run` (all nodes as processes on a private domain) and ends it the hard way:
the terminal closed (SIGHUP), SIGKILL, the recorder killed while the nodes stop, a belt too fast for the gate.
Processes are found by pid and process group (each node leads its own group, its children stay in it).
"""

from __future__ import annotations

import csv
import os
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest

from woody_tools.processes import entry_point

pytestmark = pytest.mark.ros
"""Starts `woody run` and with it every node entry point."""


def start_run(out: Path, *args: str) -> subprocess.Popen:
    """`woody run` as a terminal would start it, on a private domain of its own."""
    env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}
    return subprocess.Popen([entry_point("woody"), "run", "--out", str(out), *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=dict(env, PYTHONUNBUFFERED="1"),
                            stdin=subprocess.DEVNULL)


def _stat(pid: int) -> list[str] | None:
    """/proc/PID/stat after the command name: state, ppid, pgrp, ...; None for a process gone."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None


def _all_pids() -> list[int]:
    return [int(name) for name in os.listdir("/proc") if name.isdigit()]


def children(pid: int) -> dict[str, int]:
    """Entry point name -> pid of the processes ``pid`` started."""
    found = {}
    for child in _all_pids():
        stat = _stat(child)
        if stat and int(stat[1]) == pid:
            cmdline = Path(f"/proc/{child}/cmdline").read_bytes().split(b"\0")
            found[Path(cmdline[1].decode() if len(cmdline) > 1 else "").name] = child
    return found


def living_in_groups(groups: set[int]) -> list[tuple[int, str]]:
    """(pid, state) of every process, zombies aside, in one of the process ``groups``."""
    living = []
    for pid in _all_pids():
        stat = _stat(pid)
        if stat and int(stat[2]) in groups and stat[0] != "Z":
            living.append((pid, stat[0]))
    return living


def wait_until(predicate, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f"timed out after {timeout:g} s waiting for {what}"
        time.sleep(0.2)


def running_line(out: Path, *args: str) -> tuple[subprocess.Popen, dict[str, int]]:
    """A run whose line is under way (the gate has diverted a fillet) and its nodes' pids; line_sim's render and
    physics children are up."""
    run = start_run(out, "--duration", "120", "--k", "100", *args)
    gate_log = out / "logs" / "reject_gate.log"
    wait_until(lambda: run.poll() is not None or (gate_log.exists() and "divert fillet" in gate_log.read_text()),
               240, "the first diverted fillet")
    assert run.poll() is None, run.communicate()
    nodes = children(run.pid)
    assert set(nodes) == {"recorder", "segmenter", "grader", "reject_gate", "line_sim"}, nodes
    wait_until(lambda: len(living_in_groups({nodes["line_sim"]})) >= 3, 60, "line_sim's render and physics")
    return run, nodes


def assert_no_process_left(nodes: dict[str, int], timeout: float = 30.0) -> None:
    groups = set(nodes.values())
    deadline = time.monotonic() + timeout
    while living_in_groups(groups) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not living_in_groups(groups), f"still running: {living_in_groups(groups)} of {nodes}"


def test_closing_the_terminal_stops_the_line_and_keeps_what_was_graded(tmp_path):
    out = tmp_path / "run"
    run, nodes = running_line(out)
    run.send_signal(signal.SIGHUP)
    run.communicate(timeout=120)
    assert run.returncode == 128 + signal.SIGHUP
    assert_no_process_left(nodes)
    rows = list(csv.DictReader((out / "verdicts.csv").open()))
    assert any(r["verdict"] == "woody" for r in rows), rows
    assert "line accuracy" in (out / "report.md").read_text()
    said = (out / "logs" / "woody_run.log").read_text()  # the terminal is gone: woody run's lines go here
    assert "woody run: stopped by SIGHUP (the terminal closed)" in said and f"report: {out / 'report.md'}" in said
    assert subprocess.run([entry_point("woody"), "bag", "info", str(out / "line.mcap")], capture_output=True,
                          text=True, timeout=60).stdout.startswith(f"bag: {out / 'line.mcap'} (complete)")


def test_killing_woody_run_ends_every_node_and_its_children(tmp_path):
    """SIGKILL cannot be handled: the nodes get their parent-death signal and close (the bag is finalised)."""
    out = tmp_path / "run"
    run, nodes = running_line(out)
    run.kill()
    run.communicate(timeout=30)
    assert_no_process_left(nodes)
    info = subprocess.run([entry_point("woody"), "bag", "info", str(out / "line.mcap")], capture_output=True,
                          text=True, timeout=60)
    assert info.stdout.startswith(f"bag: {out / 'line.mcap'} (complete)"), info.stdout[:500]


def test_a_recorder_killed_while_the_nodes_stop_is_one_line_with_the_rescue(tmp_path):
    """The recorder is held (SIGSTOP) so that it is still there when woody run has stopped every other node,
    then killed: woody run names its exit code and the command that rescues the bag, and fails."""
    out = tmp_path / "run"
    run, nodes = running_line(out)
    os.kill(nodes["recorder"], signal.SIGSTOP)
    run.send_signal(signal.SIGINT)
    others = {name: pid for name, pid in nodes.items() if name != "recorder"}
    wait_until(lambda: not living_in_groups(set(others.values())), 60, "the other nodes to stop")
    assert run.poll() is None  # still stopping: waiting on the recorder
    os.kill(nodes["recorder"], signal.SIGKILL)
    _, stderr = run.communicate(timeout=120)
    assert run.returncode == 1
    bag = out / "line.mcap"
    said = [line for line in stderr.splitlines() if "recorder" in line]
    assert len(said) == 1 and said[0].startswith("woody run: recorder exited with code -9 (SIGKILL)"), stderr[-2000:]
    command = re.search(r"`(woody bag recover \S+ \S+)`", said[0]).group(1).split()
    assert command[3] == str(bag)
    rescued = subprocess.run([entry_point("woody"), *command[1:]], capture_output=True, text=True, timeout=120)
    assert rescued.returncode == 0 and Path(command[4]).stat().st_size > 0, rescued.stderr
    assert list(csv.DictReader((out / "verdicts.csv").open()))  # what was graded is kept


def test_fillets_the_gate_could_not_divert_in_time_count_as_not_diverted(tmp_path):
    """A diverter 5 cm past the roller (`--gate-distance 0.05`) must open before the fillet has crossed the edge,
    so before any verdict can reach it: reject_gate sends no command (it logs each fillet as late). report.md,
    verdicts.csv and the terminal count those fillets as not diverted. A constant cut above every score sends every
    scored fillet to the gate."""
    out = tmp_path / "run"
    run = start_run(out, "--gate-distance", "0.05", "--fillets", "6", "--k", "100", "--threshold", "1000")
    stdout, stderr = run.communicate(timeout=300)
    assert run.returncode == 0, stderr[-3000:]
    gate = re.search(r"\[reject_gate\] diverted (\d+), late (\d+), passed (\d+)",
                     (out / "logs" / "reject_gate.log").read_text())
    diverted, late = int(gate.group(1)), int(gate.group(2))
    assert late >= 1, gate.group(0)  # the reproduction: the gate was late
    rows = list(csv.DictReader((out / "verdicts.csv").open()))
    assert sum(r["gate_command"] == "none" for r in rows if r["verdict"] != "normal") == late
    assert sum(r["gate_command"] == "sent" for r in rows) == diverted
    woody = sum(r["truth"] == "woody" for r in rows)
    report = (out / "report.md").read_text()
    assert f"- diverted {diverted} of {woody} woody fillets" in report
    assert woody == len(rows) and diverted < len(rows)  # every fillet woody: right only when diverted
    assert re.search(rf"- line accuracy \(every fillet;[^)]*\): \*\*{diverted / len(rows):.1%}\*\*", report)
    assert "not diverted, no gate command: the verdict came too late to divert it" in report
    assert f"diverted {diverted} of {woody} woody fillets; {late} not diverted (no gate command" in stdout
    assert "| gate distance (m) | 0.05 |" in report
