"""Run an entry point as a user would and check its refusal: one clear line, the exit code, no traceback.

API (import with ``from bad_input.conftest import ...``; the ``entry`` fixture binds the test's domain):

- ``run_entry(*command, domain, timeout=60, cwd=None, env=None) -> Outcome``: run ``command[0]`` from
  ``.venv/bin`` with the rest as arguments on ROS domain ``domain``; ``cwd`` defaults to a fresh
  temporary folder, so nothing a refusal leaves behind goes unnoticed (see ``Outcome.cwd``).
- ``run_entries(commands, domain, **kw) -> list[Outcome]``: the same for several commands, in parallel.
- ``Outcome``: ``code``, ``stdout``, ``stderr``, ``cwd``; ``lines`` = non-blank lines of stderr then
  stdout without pybullet's import banner.
- ``assert_one_clear_line(outcome, program, contains="", code=2) -> str``: exit ``code``, no
  'Traceback' anywhere, and the output is exactly one line ``"<program>: ..."`` containing
  ``contains``; returns that line.
- fixture ``entry(*command, **kw)``: ``run_entry`` on the test's private domain (marks the test ``ros``).
"""

from __future__ import annotations

import os
import subprocess
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import pytest

from woody_tools.processes import entry_point

BANNER = "pybullet build time"
"""pybullet prints this on import, on stdout, in every process that imports it."""


@dataclass(frozen=True)
class Outcome:
    code: int
    stdout: str
    stderr: str
    cwd: Path

    @property
    def lines(self) -> list[str]:
        text = self.stderr + "\n" + self.stdout
        return [line for line in text.splitlines() if line.strip() and not line.startswith(BANNER)]


def run_entry(*command: str, domain: int, timeout: float = 60, cwd: Path | None = None,
              env: dict[str, str] | None = None) -> Outcome:
    """Run an entry point to its end (killed after ``timeout`` s, which fails the test)."""
    cwd = Path(cwd) if cwd is not None else Path(tempfile.mkdtemp(prefix="bad_input_"))
    full_env = dict(os.environ if env is None else env, ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED="1")
    result = subprocess.run([entry_point(command[0]), *command[1:]], capture_output=True, text=True,
                            timeout=timeout, env=full_env, cwd=cwd, stdin=subprocess.DEVNULL)
    return Outcome(result.returncode, result.stdout, result.stderr, cwd)


def run_entries(commands, domain: int, **kw) -> list[Outcome]:
    """Run independent commands at the same time; outcomes in the order given."""
    with ThreadPoolExecutor(max_workers=max(1, len(commands))) as pool:
        return list(pool.map(lambda command: run_entry(*command, domain=domain, **kw), commands))


def assert_one_clear_line(outcome: Outcome, program: str, contains: str = "", code: int = 2) -> str:
    """The refusal is one line prefixed by the program's name, with the exit code and no traceback."""
    shown = "\n".join(outcome.lines)
    assert "Traceback" not in outcome.stderr + outcome.stdout, shown
    assert outcome.code == code, f"exit {outcome.code}, wanted {code}:\n{shown}"
    assert len(outcome.lines) == 1, f"wanted one line:\n{shown}"
    line = outcome.lines[0]
    assert line.startswith(f"{program}: ") and contains in line, line
    return line


@pytest.fixture
def entry(ros_domain):
    """``run_entry`` on the test's private ROS domain."""
    return lambda *command, **kw: run_entry(*command, domain=ros_domain, **kw)
