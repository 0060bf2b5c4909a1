"""Run an entry point as a user would and check its refusal: one clear line, the exit code, no traceback.

API (import with ``from bad_input.conftest import ...``; the ``entry`` fixture binds the test's domain):

- ``run_entry(*command, domain, timeout=60, cwd=None, env=None) -> Outcome``: run ``command[0]`` from
  ``.venv/bin`` with the rest as arguments on ROS domain ``domain`` (None: ``ROS_DOMAIN_ID`` unset, as
  for `woody run`, which leases a domain of its own), leading its own process group; ``cwd``
  defaults to a fresh temporary folder, so nothing a refusal leaves behind goes unnoticed (see
  ``Outcome.cwd``). A command still running after ``timeout`` s is killed with its children and has
  ``code`` None (it was not refused).
- ``run_entries(commands, domain, workers=4, **kw) -> list[Outcome]``: several commands, ``workers`` at a time.
- ``Outcome``: ``code``, ``stdout``, ``stderr``, ``cwd``; ``lines`` = non-blank lines of stderr then
  stdout without pybullet's import banner.
- ``assert_one_clear_line(outcome, program, contains="", code=2) -> str``: exit ``code``, no
  'Traceback' anywhere, and the output is exactly one line ``"<program>: ..."`` containing
  ``contains``; returns that line.
- fixture ``entry(*command, **kw)``: ``run_entry`` on the test's private domain (marks the test ``ros``).
"""

from __future__ import annotations

import atexit
import functools
import os
import shutil
import signal
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
    code: int | None
    stdout: str
    stderr: str
    cwd: Path

    @property
    def lines(self) -> list[str]:
        text = self.stderr + "\n" + self.stdout
        return [line for line in text.splitlines() if line.strip() and not line.startswith(BANNER)]


@functools.cache
def _scratch() -> Path:
    """One folder for the working directories of every entry point run here, removed when the tests end."""
    path = Path(tempfile.mkdtemp(prefix="bad_input_"))
    atexit.register(shutil.rmtree, path, ignore_errors=True)
    return path


def run_entry(*command: str, domain: int | None, timeout: float = 60, cwd: Path | None = None,
              env: dict[str, str] | None = None) -> Outcome:
    """Run an entry point to its end, or kill it and its children after ``timeout`` s (code None)."""
    cwd = Path(cwd) if cwd is not None else Path(tempfile.mkdtemp(prefix="run_", dir=_scratch()))
    full_env = {k: v for k, v in (os.environ if env is None else env).items() if k != "ROS_DOMAIN_ID"}
    full_env.update(PYTHONUNBUFFERED="1", **({} if domain is None else {"ROS_DOMAIN_ID": str(domain)}))
    proc = subprocess.Popen([entry_point(command[0]), *command[1:]], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=full_env, cwd=cwd, stdin=subprocess.DEVNULL, start_new_session=True)
    try:
        stdout, stderr = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        stdout, stderr = proc.communicate()
        return Outcome(None, stdout, stderr, cwd)
    return Outcome(proc.returncode, stdout, stderr, cwd)


def run_entries(commands, domain: int | None, workers: int = 4, **kw) -> list[Outcome]:
    """Run independent commands ``workers`` at a time (2 cores: more only queue); outcomes in the order given."""
    with ThreadPoolExecutor(max_workers=workers) as pool:
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
