"""CPU accounting per process tree: a node's children count for it, exited children are remembered."""

from __future__ import annotations

import subprocess
import sys
import time

from woody_tools.cpu_usage import CpuAccounting

BUSY = "import time\nt = time.process_time()\nwhile time.process_time() - t < {s}: pass\n"


def test_a_tree_is_charged_its_children_and_idle_roots_nothing():
    child = BUSY.format(s=0.4)
    parent = (f"import subprocess, sys, time\np = subprocess.Popen([sys.executable, '-c', {child!r}])\n"
              + BUSY.format(s=0.2) + "time.sleep(5)\n")
    busy = subprocess.Popen([sys.executable, "-c", parent])
    idle = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(5)"])
    try:
        cpu = CpuAccounting({"busy": busy.pid, "idle": idle.pid})
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline and sum(cpu.children().get("busy", {}).values()) < 0.4:
            cpu.sample()
            time.sleep(0.05)
        per = cpu.per_root()
        assert 0.6 <= per["busy"] < 2.0  # 0.2 s own + 0.4 s of its child, which exits unreaped
        assert per["idle"] < 0.3
        assert cpu.summary(10.0).splitlines()[1].split()[0] == "busy"
        assert 0.3 <= sum(cpu.children()["busy"].values()) < 1.5 and "idle" not in cpu.children()
    finally:
        for p in (busy, idle):
            p.kill()
            p.wait()
