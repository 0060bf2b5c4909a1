"""A worker process on the second core, spoken to over a pipe.

line_sim runs its renderer (:class:`~woody_sim.rendering.RenderProcess`) and half of its physics
(:class:`~woody_sim.split_world.SplitLineWorld`) in child processes. Both need the same care: the child
starts with Ctrl-C ignored (the parent decides when it stops), is named so that ``top`` and ``woody run``'s
CPU table can tell it apart, ends as soon as its parent dies, and a parent waiting on it learns at once
when it died instead of hanging.
"""

from __future__ import annotations

import ctypes
import multiprocessing as mp
import multiprocessing.connection as mpc
import signal
import threading
import time
import weakref
from collections.abc import Callable, Iterator
from typing import Any


class ChildProcess:
    """A daemon process running ``target(conn, *args)``; ``send`` and ``recv`` talk to it over ``conn``."""

    def __init__(self, target: Callable[..., None], args: tuple, name: str, start_method: str = "spawn",
                 timeout: float = 30.0) -> None:
        self.name = name
        self._timeout = float(timeout)
        ctx = mp.get_context(start_method)
        self._conn, child_conn = ctx.Pipe(duplex=True)
        self._proc = ctx.Process(target=target, args=(child_conn, *args), name=name, daemon=True)
        self._start_ignoring_sigint()
        child_conn.close()
        self._closed = False
        self._finalizer = weakref.finalize(self, ChildProcess._shutdown, self._conn, self._proc)

    def _start_ignoring_sigint(self) -> None:
        """Start the child with SIGINT ignored from its first instruction: a Ctrl-C that reaches the process
        group while the child is still importing would otherwise end it in a KeyboardInterrupt traceback
        (an ignored disposition survives exec, and Python keeps it). The parent's handler is restored."""
        if threading.current_thread() is not threading.main_thread():
            self._proc.start()
            return
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            self._proc.start()
        finally:
            signal.signal(signal.SIGINT, previous)

    @staticmethod
    def _shutdown(conn: mpc.Connection, proc: Any) -> None:
        try:
            conn.send(("close",))
        except (OSError, ValueError):
            pass
        proc.join(timeout=2.0)
        if proc.is_alive():
            proc.terminate()
            proc.join(timeout=2.0)
        if proc.is_alive():
            proc.kill()
            proc.join(timeout=1.0)
        try:
            conn.close()
        except OSError:
            pass

    def close(self) -> None:
        """Ask the child to stop, and end it if it does not within 2 s."""
        if not self._closed:
            self._closed = True
            self._finalizer()

    @property
    def pid(self) -> int | None:
        return self._proc.pid

    def is_alive(self) -> bool:
        return self._proc.is_alive()

    def _check_alive(self) -> None:
        if not self._proc.is_alive():
            raise RuntimeError(f"{self.name} process died (exit code {self._proc.exitcode})")

    def _died(self) -> RuntimeError:
        """The error for a pipe the child's end of has gone: it died (wait a moment to learn its exit code)."""
        self._proc.join(timeout=1.0)
        return RuntimeError(f"{self.name} process died (exit code {self._proc.exitcode})")

    def send(self, msg: tuple) -> None:
        if self._closed:
            raise RuntimeError(f"{self.name} process is closed")
        self._check_alive()
        try:
            self._conn.send(msg)
        except (BrokenPipeError, ConnectionResetError):
            raise self._died() from None

    def poll(self) -> bool:
        """A message from the child is waiting."""
        return self._conn.poll()

    def recv(self) -> Any:
        """The child's next message; RuntimeError if it dies first, TimeoutError after ``timeout`` seconds."""
        deadline = time.monotonic() + self._timeout
        while not self._conn.poll(0.05):
            self._check_alive()
            if time.monotonic() > deadline:
                raise TimeoutError(f"{self.name} process did not answer")
        try:
            return self._conn.recv()
        except (EOFError, ConnectionResetError):
            raise self._died() from None


def name_process(name: bytes) -> None:
    """Name this process as top and /proc show it (Linux PR_SET_NAME), so its CPU is attributed by name."""
    try:
        ctypes.CDLL(None).prctl(15, name, 0, 0, 0)
    except (OSError, AttributeError):
        pass


def parent_messages(conn: mpc.Connection, name: bytes) -> Iterator[tuple]:
    """In the child: ignore Ctrl-C, end on SIGTERM, take ``name``, and yield the parent's messages until it sends
    ``("close",)``, closes the pipe or dies. A forked child inherits its parent's SIGTERM handler (a node's stop
    flag), which would leave it running when multiprocessing ends its daemons at the parent's exit."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    name_process(name)
    parent = mp.parent_process()
    waitables = [conn] + ([parent.sentinel] if parent is not None else [])
    while True:
        if conn not in mpc.wait(waitables):  # the parent died
            return
        try:
            msg = conn.recv()
        except (EOFError, OSError):
            return
        if msg[0] == "close":
            return
        yield msg
