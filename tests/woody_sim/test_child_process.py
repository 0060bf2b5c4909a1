"""ChildProcess and parent_messages: a pipe-driven worker that ignores Ctrl-C and whose death is noticed."""

from __future__ import annotations

import os
import signal
import time

import pytest

from woody_sim.child_process import ChildProcess, parent_messages


def echo(conn) -> None:
    """Answers ("echo", x) with x, ("sleep", s) after s seconds, and names its SIGINT disposition on ("sigint",)."""
    for msg in parent_messages(conn, b"woody-test"):
        if msg[0] == "echo":
            conn.send(msg[1])
        elif msg[0] == "sleep":
            time.sleep(msg[1])
            conn.send("awake")
        elif msg[0] == "sigint":
            conn.send(signal.getsignal(signal.SIGINT) == signal.SIG_IGN)
        elif msg[0] == "name":
            conn.send(open(f"/proc/{os.getpid()}/comm").read().strip())


def test_messages_go_both_ways_and_close_ends_the_child():
    child = ChildProcess(echo, (), "echo")
    child.send(("echo", [1, 2]))
    assert child.recv() == [1, 2]
    child.send(("name",))
    assert child.recv() == "woody-test"
    child.close()
    assert not child.is_alive()
    with pytest.raises(RuntimeError, match="closed"):
        child.send(("echo", 1))


def test_the_child_ignores_ctrl_c():
    child = ChildProcess(echo, (), "echo")
    child.send(("sigint",))
    assert child.recv() is True
    os.kill(child.pid, signal.SIGINT)
    child.send(("echo", "still here"))
    assert child.recv() == "still here"
    child.close()


def test_a_dead_child_is_an_error_at_once_and_a_silent_one_after_the_timeout():
    child = ChildProcess(echo, (), "echo")
    child.send(("echo", 0))
    child.recv()
    os.kill(child.pid, signal.SIGKILL)
    start = time.monotonic()
    with pytest.raises(RuntimeError, match="echo process died"):
        child.recv()
    assert time.monotonic() - start < 5.0
    slow = ChildProcess(echo, (), "slow", timeout=0.3)
    slow.send(("sleep", 5.0))
    with pytest.raises(TimeoutError, match="slow process did not answer"):
        slow.recv()
    slow.close()
