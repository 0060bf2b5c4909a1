"""Where the CPU went: CPU seconds per process tree, read from /proc (Linux).

A node's cost includes its children (line_sim's render process), so each
root pid is followed with its descendants. Processes are sampled while they
run: a child that exits is remembered at its last sample, since /proc only
adds children's times to the parent once they are reaped.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

_TICK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def _stat(pid: int) -> tuple[int, float, str] | None:
    """(parent pid, user + system CPU seconds, command name) of a live process, or None."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    name = text[text.index("(") + 1:text.rindex(")")]
    fields = text[text.rindex(")") + 2:].split()
    return int(fields[1]), (int(fields[11]) + int(fields[12])) / _TICK, name


def cpu_seconds(pid: int) -> float:
    """User + system CPU seconds of one live process so far (its children not included); NaN once it is gone."""
    stat = _stat(pid)
    return stat[1] if stat is not None else math.nan


class CpuAccounting:
    """CPU seconds of named process trees, accumulated by :meth:`sample` calls."""

    def __init__(self, roots: dict[str, int]) -> None:
        self.roots = dict(roots)
        self._seen: dict[int, tuple[str, float, str]] = {}  # pid -> (root name, cpu s, command)

    def sample(self) -> None:
        stats = {}
        for entry in os.listdir("/proc"):
            if entry.isdigit():
                st = _stat(int(entry))
                if st is not None:
                    stats[int(entry)] = st
        owner = {pid: name for name, pid in self.roots.items()}
        pending = [pid for pid in stats if pid not in owner]
        while pending:  # assign descendants to the root above them
            rest = [pid for pid in pending if stats[pid][0] not in owner]
            for pid in pending:
                if stats[pid][0] in owner:
                    owner[pid] = owner[stats[pid][0]]
            if len(rest) == len(pending):
                break
            pending = rest
        for pid, name in owner.items():
            if pid in stats:
                self._seen[pid] = (name, stats[pid][1], stats[pid][2])

    def per_root(self) -> dict[str, float]:
        """CPU seconds per root name (its whole tree)."""
        out = {name: 0.0 for name in self.roots}
        for name, cpu, _ in self._seen.values():
            out[name] += cpu
        return out

    def summary(self, wall_s: float) -> str:
        """One line per root, most expensive first, with its share of two cores' wall time."""
        per = sorted(self.per_root().items(), key=lambda kv: -kv[1])
        total = sum(cpu for _, cpu in per)
        lines = [f"CPU per node over {wall_s:.1f} s wall ({total:.1f} CPU-s in all, "
                 f"{100.0 * total / max(2.0 * wall_s, 1e-9):.0f} % of 2 cores):"]
        children = self.children()
        width = max((len(name) for name, _ in per), default=12)
        for name, cpu in per:
            part = ", ".join(f"{command} {seconds:.1f} s" for command, seconds in children.get(name, {}).items())
            lines.append(f"  {name:<{width}} {cpu:7.1f} s  {100.0 * cpu / max(total, 1e-9):5.1f} %"
                         + (f"  (child processes: {part})" if part else ""))
        return "\n".join(lines)

    def children(self) -> dict[str, dict[str, float]]:
        """CPU seconds of each root's descendants, by command name (e.g. line_sim's render process)."""
        out: dict[str, dict[str, float]] = {}
        for pid, (name, cpu, command) in self._seen.items():
            if pid != self.roots[name] and cpu >= 0.05:
                out.setdefault(name, {})
                out[name][command] = out[name].get(command, 0.0) + cpu
        return out
