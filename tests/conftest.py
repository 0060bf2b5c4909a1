"""Shared fixtures: a private ROS domain per test and an rclpy context on it; the ``ros`` marker.

A test that uses a ROS domain (``ros_domain``, ``ros_node``, ``spawn_helper``) is marked ``ros``
here; modules that start entry points by other ways mark themselves (``pytestmark``).
`make test-unit` runs ``pytest -m "not ros"``.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
TESTS = REPO / "tests"
FIXTURES = TESTS / "fixtures"
"""Helper processes the graph tests start (publishers, a replay wrapper)."""
ROS_FIXTURES = {"ros_domain", "ros_node", "spawn_helper"}
"""Fixtures that put a test on a ROS graph: their tests get the ``ros`` marker."""


def pytest_collection_modifyitems(items) -> None:
    for item in items:
        if ROS_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.ros)


def fixture_env(domain_id: int) -> dict[str, str]:
    """Environment of a helper process: the test's domain, unbuffered output, tests/ importable (msg_samples)."""
    path = os.pathsep.join(p for p in (str(TESTS), os.environ.get("PYTHONPATH", "")) if p)
    return dict(os.environ, ROS_DOMAIN_ID=str(domain_id), PYTHONUNBUFFERED="1", PYTHONPATH=path)


@pytest.fixture
def ros_domain():
    """A ROS domain id that no other test or run on this machine is using."""
    from woody_tools.processes import lease_domain

    env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}
    with lease_domain(env) as lease:
        yield lease.domain_id


@pytest.fixture
def ros_node(ros_domain):
    """An rclpy node in its own context on the test's private domain."""
    import rclpy

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=ros_domain)
    node = rclpy.create_node("pytest_probe", context=context)
    yield node
    node.destroy_node()
    rclpy.try_shutdown(context=context)


@pytest.fixture
def spawn_helper(ros_domain, tmp_path):
    """Start `python tests/fixtures/<script>.py args...` on the test's domain; killed after the test."""
    procs = []

    def start(script: str, *args: str) -> subprocess.Popen:
        log = open(tmp_path / f"{script}.log", "w")
        proc = subprocess.Popen([sys.executable, str(FIXTURES / f"{script}.py"), *args],
                                stdout=log, stderr=subprocess.STDOUT, env=fixture_env(ros_domain))
        procs.append((proc, log))
        return proc

    yield start
    for proc, log in procs:
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(5)
            except subprocess.TimeoutExpired:
                proc.kill()
        log.close()


def spin_until(node, predicate, timeout: float) -> bool:
    """Spin ``node`` until ``predicate()`` is true or ``timeout`` seconds pass."""
    import time

    import rclpy

    executor = rclpy.executors.SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    deadline = time.monotonic() + timeout
    try:
        while time.monotonic() < deadline and not predicate():
            executor.spin_once(timeout_sec=0.05)
    finally:
        executor.remove_node(node)
    return predicate()
