"""Where line_sim's loop spends its wall time, phase by phase.

line_sim logs the split when it stops, and `woody bench sim` prints it, so a line that falls behind real time
says whether the physics, the wait for a physics worker, the renderer or the publishing holds it back.
"""

from __future__ import annotations

import re
import time

SUMMARY_PREFIX = "wall time by phase:"
"""How the closing log line starts (`woody bench sim` finds it by this)."""


class PhaseClock:
    """Accumulates wall time per named phase: each :meth:`lap` charges the time since the previous one."""

    def __init__(self) -> None:
        self.totals: dict[str, float] = {}
        self._last = time.perf_counter()

    def lap(self, phase: str) -> None:
        now = time.perf_counter()
        self.totals[phase] = self.totals.get(phase, 0.0) + (now - self._last)
        self._last = now

    def summary(self) -> str:
        """One line: every phase's share of the timed wall time, largest first."""
        total = sum(self.totals.values()) or 1.0
        parts = [f"{name} {100.0 * seconds / total:.1f} %"
                 for name, seconds in sorted(self.totals.items(), key=lambda item: -item[1])]
        return f"{SUMMARY_PREFIX} " + ", ".join(parts)


def parse_summary(text: str) -> dict[str, float]:
    """Phase -> percent of wall time, from the last summary line in ``text`` (empty if there is none)."""
    lines = [line for line in text.splitlines() if SUMMARY_PREFIX in line]
    if not lines:
        return {}
    body = lines[-1].split(SUMMARY_PREFIX, 1)[1]
    return {name: float(value) for name, value in re.findall(r"([a-z_]+) ([0-9.]+) %", body)}
