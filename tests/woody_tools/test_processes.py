"""Starting nodes: parameters become a params file, namespaces the right --ros-args."""

from __future__ import annotations

from woody_tools.processes import namespace_args, write_params_file


def test_a_namespace_moves_the_node_and_gives_it_its_own_clock():
    assert namespace_args("") == []
    for ns in ("line2", "/line2", "/line2/"):
        assert namespace_args(ns) == ["-r", "__ns:=/line2", "-r", "/clock:=/line2/clock"]


def test_parameters_go_to_a_params_file_unchanged(tmp_path):
    import yaml

    params = {"lanes": 3, "speed": 130.0, "realtime": False, "k": [0.0, 100.0], "output": "/tmp/run #1: x/line.mcap"}
    path = write_params_file(tmp_path / "p.yaml", params)
    assert yaml.safe_load(path.read_text()) == {"/**": {"ros__parameters": params}}


def _gone(pid: int) -> bool:
    try:
        return open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0] == "Z"
    except OSError:
        return True


def test_a_child_started_with_end_with_parent_ends_when_its_parent_is_killed():
    """The parent-death signal reaches the child even when the parent dies by SIGKILL (it cannot clean up)."""
    import subprocess
    import sys
    import time

    parent = subprocess.Popen([sys.executable, "-c", (
        "import os, subprocess, time\n"
        "from woody_tools.processes import end_with_parent\n"
        "child = subprocess.Popen(['sleep', '120'], start_new_session=True, preexec_fn=end_with_parent(os.getpid()))\n"
        "print(child.pid, flush=True)\n"
        "time.sleep(120)\n")], stdout=subprocess.PIPE, text=True)
    child = int(parent.stdout.readline())
    assert not _gone(child)
    parent.kill()
    parent.wait(10)
    deadline = time.monotonic() + 10
    while not _gone(child) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert _gone(child)


def test_a_stop_signal_survives_code_that_swallows_keyboard_interrupt():
    """What lost Ctrl-C in the first second of `woody run`: an import that catches BaseException."""
    import subprocess
    import sys

    script = ("import os, signal\n"
              "from woody_tools.processes import STOP\n"
              "STOP.install()\n"
              "try:\n"
              "    os.kill(os.getpid(), signal.SIGINT)\n"
              "except BaseException:\n"
              "    pass\n"
              "print(STOP.name)\n")
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=30)
    assert result.stdout.strip() == "SIGINT", result.stderr
