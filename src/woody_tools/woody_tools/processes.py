"""Start woody nodes as separate processes on a private ROS domain.

`woody run` and the integration tests both start real entry points this way:
each node is its own process, all share one ``ROS_DOMAIN_ID`` that no other
run on this machine holds (a lock file per id), so parallel runs and tests
never see each other's topics. A user's own ``ROS_DOMAIN_ID`` is respected
but locked the same way, so a second run on it is refused rather than mixed.
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import IO

MAX_DOMAIN_ID = 232
"""Highest domain id whose Fast DDS ports stay valid."""
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
"""Signals that end a run the way Ctrl-C does: Ctrl-C, a polite kill, the terminal closed."""
PARENT_DEATH_SIGNAL = signal.SIGTERM
"""What a node gets when its parent dies, even by SIGKILL: every node closes cleanly on it (the recorder finalises
its bag)."""
_PR_SET_PDEATHSIG = 1
_LIBC = ctypes.CDLL(None, use_errno=True)


class StopRequest:
    """The first of STOP_SIGNALS received, kept as a flag rather than raised.

    A KeyboardInterrupt raised while `woody run` imports its modules is lost when it lands in an import that
    catches BaseException (trimesh guards its optional dependencies so); a flag, checked by the run at every
    stage, is not. After SIGHUP the terminal is gone and writing to it fails, so the process's output goes
    to ``hangup_log`` (or nowhere) from then on.
    """

    def __init__(self) -> None:
        self.signum: int | None = None
        self.hangup_log: Path | None = None

    def install(self) -> None:
        for sig in STOP_SIGNALS:
            signal.signal(sig, self._on_signal)

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name if self.signum else ""

    def _on_signal(self, signum: int, _frame: object) -> None:
        self.signum = self.signum or signum
        if signum == signal.SIGHUP:
            _redirect_output(self.hangup_log)


STOP = StopRequest()
"""This process's stop request (`woody run` installs it before its first slow import)."""


def _redirect_output(path: Path | None) -> None:
    """Send file descriptors 1 and 2 to ``path`` (appended), or to /dev/null without one; what Python still
    buffers goes there too (no flush here: the handler may interrupt a write)."""
    target = os.devnull
    if path is not None:
        with contextlib.suppress(OSError):
            path.parent.mkdir(parents=True, exist_ok=True)
            target = str(path)
    fd = os.open(target, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    os.close(fd)


class DomainLease:
    """A ROS domain id held exclusively by this process until `release()`.

    ``exported`` is True for the user's own ROS_DOMAIN_ID, which programs other than woody may share.
    """

    def __init__(self, domain_id: int, lock_file: IO | None, exported: bool = False) -> None:
        self.domain_id = domain_id
        self.exported = exported
        self._lock_file = lock_file

    def release(self) -> None:
        if self._lock_file is not None:
            fcntl.flock(self._lock_file, fcntl.LOCK_UN)
            self._lock_file.close()
            self._lock_file = None

    def __enter__(self) -> DomainLease:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


class DomainInUse(RuntimeError):
    """The exported ROS_DOMAIN_ID is held by another woody run on this machine."""


def _try_lock(lock_dir: Path, domain_id: int) -> IO | None:
    handle = open(lock_dir / f"{domain_id}.lock", "w")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        handle.close()
        return None
    return handle


def lease_domain(env: dict[str, str] | None = None, *, share: bool = False) -> DomainLease:
    """The user's ROS_DOMAIN_ID if set (locked too: `DomainInUse` when another run holds it, unless
    ``share``), else a free id locked for this process."""
    env = os.environ if env is None else env
    lock_dir = Path(tempfile.gettempdir()) / "woody-domains"
    lock_dir.mkdir(exist_ok=True)
    if env.get("ROS_DOMAIN_ID"):
        if not env["ROS_DOMAIN_ID"].strip().isdigit() or int(env["ROS_DOMAIN_ID"]) > MAX_DOMAIN_ID:
            raise ValueError(f"ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']!r} is not a domain id (0..{MAX_DOMAIN_ID})")
        domain_id = int(env["ROS_DOMAIN_ID"])
        handle = _try_lock(lock_dir, domain_id)
        if handle is None and not share:
            raise DomainInUse(f"ROS_DOMAIN_ID={domain_id} (exported) is in use by another woody run on this "
                              "machine; the two would mix. Unset ROS_DOMAIN_ID to get a private domain, "
                              "or pass --share-domain to mix on purpose")
        return DomainLease(domain_id, handle, exported=True)
    candidates = list(range(1, MAX_DOMAIN_ID + 1))
    random.shuffle(candidates)
    for domain_id in candidates:
        handle = _try_lock(lock_dir, domain_id)
        if handle is not None:
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


def write_params_file(path: Path, params: dict[str, object]) -> Path:
    """A ROS 2 parameters file for every node of the process: values are YAML-quoted, so paths with
    ``#``, ``: `` or spaces arrive unchanged (``-p name:=value`` on a command line would cut them)."""
    import yaml

    path.write_text(yaml.safe_dump({"/**": {"ros__parameters": dict(params)}}, allow_unicode=True))
    return path


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


class NodeProcess:
    """One entry point running as a child process, its output going to a log file.

    The node leads its own process group (a Ctrl-C in the terminal reaches only its parent, which stops the
    nodes in order) and gets PARENT_DEATH_SIGNAL when its parent dies. The kernel ties that signal to the
    thread that started the node: start nodes from a thread that lives as long as they should (the main one).
    """

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
        if params:
            params_file = write_params_file(self.log_path.with_suffix(".params.yaml"), params)
            cmd += ["--ros-args", "--params-file", str(params_file)]
        if namespace:
            cmd += ["--ros-args", *namespace_args(namespace)]
        self.command = cmd
        self._log = open(self.log_path, "w")
        self._sent: set[int] = set()
        self.process = subprocess.Popen(
            cmd, stdout=self._log, stderr=subprocess.STDOUT, env=child_env, start_new_session=True,
            preexec_fn=end_with_parent(os.getpid()),
        )

    @property
    def returncode(self) -> int | None:
        return self.process.poll()

    def alive(self) -> bool:
        return self.process.poll() is None

    def signal(self, sig: int) -> None:
        if self.alive():
            self.process.send_signal(sig)
            self._sent.add(sig)

    def stop(self, timeout: float = 10.0) -> int:
        """SIGINT (unless `signal` already sent it: a second one would cut the node's clean shutdown short),
        then SIGTERM, then SIGKILL; returns the exit code."""
        for sig, wait in ((signal.SIGINT, timeout), (signal.SIGTERM, 3.0), (signal.SIGKILL, 3.0)):
            if not self.alive():
                break
            if sig not in self._sent:
                self.signal(sig)
            try:
                self.process.wait(wait)
            except subprocess.TimeoutExpired:
                continue
        code = self.process.wait()
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(self.process.pid, signal.SIGKILL)  # a child of the node still in its process group
        self._log.close()
        return code

    def log_tail(self, lines: int = 20) -> str:
        try:
            return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-lines:])
        except OSError:
            return ""


def end_with_parent(parent_pid: int):
    """The child's set-up between fork and exec: PARENT_DEATH_SIGNAL when this process dies, however it dies; a
    parent already gone (it died during the fork) ends the child at once. Only the preloaded prctl is called."""
    def set_up() -> None:
        _LIBC.prctl(_PR_SET_PDEATHSIG, int(PARENT_DEATH_SIGNAL), 0, 0, 0)
        if os.getppid() != parent_pid:
            os._exit(1)
    return set_up


def wait_for(predicate, timeout: float, interval: float = 0.05) -> bool:
    """Poll ``predicate`` until it is true or ``timeout`` seconds pass."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(interval)
    return bool(predicate())
