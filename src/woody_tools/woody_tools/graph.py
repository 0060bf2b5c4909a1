"""Start woody nodes as separate processes on a private ROS domain.

`woody run` and the integration tests both start real entry points this way:
each node is its own process, all share one ``ROS_DOMAIN_ID`` that no other
run on this machine holds (a lock file per id), so parallel runs and tests
never see each other's topics. A user's own ``ROS_DOMAIN_ID`` is respected.
"""

from __future__ import annotations

import fcntl
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import IO, Sequence

MAX_DOMAIN_ID = 232
"""Highest domain id whose Fast DDS ports stay valid."""


class DomainLease:
    """A ROS domain id held exclusively by this process until `release()`."""

    def __init__(self, domain_id: int, lock_file: IO | None) -> None:
        self.domain_id = domain_id
        self._lock_file = lock_file

    def release(self) -> None:
        if self._lock_file is not None:
            fcntl.flock(self._lock_file, fcntl.LOCK_UN)
            self._lock_file.close()
            self._lock_file = None

    def __enter__(self) -> "DomainLease":
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def lease_domain(env: dict[str, str] | None = None) -> DomainLease:
    """The user's ROS_DOMAIN_ID if set, else a free id locked for this process."""
    env = os.environ if env is None else env
    if env.get("ROS_DOMAIN_ID"):
        return DomainLease(int(env["ROS_DOMAIN_ID"]), None)
    lock_dir = Path(tempfile.gettempdir()) / "woody-domains"
    lock_dir.mkdir(exist_ok=True)
    candidates = list(range(1, MAX_DOMAIN_ID + 1))
    random.shuffle(candidates)
    for domain_id in candidates:
        handle = open(lock_dir / f"{domain_id}.lock", "w")
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        return DomainLease(domain_id, handle)
    raise RuntimeError(f"no free ROS domain id in 1..{MAX_DOMAIN_ID} (lock files in {lock_dir})")


def entry_point(name: str) -> str:
    """Path of a console script installed beside this interpreter."""
    candidate = Path(sys.executable).parent / name
    if candidate.exists():
        return str(candidate)
    found = shutil.which(name)
    if found is None:
        raise FileNotFoundError(f"entry point '{name}' not found beside {sys.executable} or on PATH")
    return found


def ros_args(params: dict[str, object]) -> list[str]:
    """``--ros-args -p name:=value ...`` for a parameter dict."""
    args = ["--ros-args"]
    for key, value in params.items():
        if isinstance(value, bool):
            text = "true" if value else "false"
        elif isinstance(value, (list, tuple)):
            text = "[" + ",".join(_scalar(v) for v in value) + "]"
        else:
            text = _scalar(value)
        args += ["-p", f"{key}:={text}"]
    return args


def namespace_args(namespace: str) -> list[str]:
    """``-r`` rules that move a node into ``namespace`` with its own sim clock ("" = none).

    The nodes' topic names are relative (REP 135), so ``__ns`` moves them all;
    ``/clock`` is absolute by ROS convention (every ``use_sim_time`` node listens
    to it), so each namespaced line gets ``<ns>/clock`` and two simulated lines
    in one domain do not drive each other's time.
    """
    if not namespace:
        return []
    ns = "/" + namespace.strip("/")
    return ["-r", f"__ns:={ns}", "-r", f"/clock:={ns}/clock"]


def _scalar(value: object) -> str:
    if isinstance(value, str):
        return value if value else "''"
    return repr(value) if isinstance(value, float) else str(value)


class NodeProcess:
    """One entry point running as a child process, its output going to a log file."""

    def __init__(
        self,
        name: str,
        params: dict[str, object] | None = None,
        *,
        domain_id: int,
        log_dir: Path,
        extra_args: Sequence[str] = (),
        env: dict[str, str] | None = None,
        namespace: str = "",
    ) -> None:
        self.name = name
        self.log_path = Path(log_dir) / f"{name}.log"
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        child_env = dict(os.environ if env is None else env)
        child_env["ROS_DOMAIN_ID"] = str(domain_id)
        child_env.setdefault("PYTHONUNBUFFERED", "1")
        cmd = [entry_point(name), *extra_args]
        if params or namespace:
            cmd += ros_args(params or {}) + namespace_args(namespace)
        self.command = cmd
        self._log = open(self.log_path, "w")
        self.process = subprocess.Popen(
            cmd, stdout=self._log, stderr=subprocess.STDOUT, env=child_env, start_new_session=True
        )

    @property
    def returncode(self) -> int | None:
        return self.process.poll()

    def alive(self) -> bool:
        return self.process.poll() is None

    def signal(self, sig: int) -> None:
        if self.alive():
            self.process.send_signal(sig)

    def stop(self, timeout: float = 10.0) -> int:
        """SIGINT, then SIGTERM, then SIGKILL; returns the exit code."""
        for sig, wait in ((signal.SIGINT, timeout), (signal.SIGTERM, 3.0), (signal.SIGKILL, 3.0)):
            if not self.alive():
                break
            self.process.send_signal(sig)
            try:
                self.process.wait(wait)
            except subprocess.TimeoutExpired:
                continue
        code = self.process.wait()
        self._log.close()
        return code

    def log_tail(self, lines: int = 20) -> str:
        try:
            return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-lines:])
        except OSError:
            return ""


def wait_for(predicate, timeout: float, interval: float = 0.05) -> bool:
    """Poll ``predicate`` until it is true or ``timeout`` seconds pass."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(interval)
    return bool(predicate())
