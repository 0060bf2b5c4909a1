"""`woody_common.ros_params`: declared parameters are read-only, whole numbers are taken for decimal
parameters (``-p line_speed_fpm:=130``) with the range still enforced, and every node stops cleanly on
SIGINT/SIGTERM with one summary line.

Bad parameters on every node's command line (unknown names, malformed overrides, stray arguments,
``--help``, empty lists, NaN, out of range, a runtime set) are in tests/bad_input/test_parameters.py.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess

import pytest
import rclpy
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.parameter import Parameter

from woody_common.ros_params import declare
from woody_tools.processes import entry_point

pytestmark = pytest.mark.ros
"""Starts node entry points or `woody` as processes."""

NODES = ["line_sim", "segmenter", "grader", "reject_gate", "recorder"]


def test_declared_parameters_are_read_only():
    import rclpy
    from rclpy.node import Node

    from woody_common.ros_params import declare

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=0)
    try:
        node = Node("probe", context=context)
        declare(node, "lanes", 3, "Lanes.", 1, 6)
        assert node.describe_parameter("lanes").read_only
        result = node.set_parameters([rclpy.parameter.Parameter("lanes", value=4)])[0]
        assert not result.successful and node.get_parameter("lanes").value == 3
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


SUMMARIES = {"line_sim": "stopped at sim time", "segmenter": "[segmenter] ", "grader": "[grader] published",
             "reject_gate": "[reject_gate] diverted", "recorder": "wrote "}


def handles_stop_signals(pid: int) -> bool:
    """True once the process catches SIGINT and SIGTERM (its handlers are installed)."""
    import signal

    try:
        status = open(f"/proc/{pid}/status").read()
    except OSError:
        return False
    caught = int(status.split("SigCgt:")[1].split()[0], 16)
    return all(caught >> (sig - 1) & 1 for sig in (signal.SIGINT, signal.SIGTERM))


@pytest.mark.parametrize("node,sig", [(n, "SIGINT") for n in NODES]
                         + [("line_sim", "SIGTERM"), ("grader", "SIGTERM"), ("recorder", "SIGTERM")])
def test_every_node_stops_cleanly_with_one_summary_line(ros_domain, tmp_path, node, sig):
    """SIGINT to the whole process group (a terminal's Ctrl-C reaches line_sim's render process too) or SIGTERM."""
    import signal
    import time

    from woody_tools.processes import wait_for

    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain), PYTHONUNBUFFERED="1")
    log = tmp_path / "node.log"
    extra = ["--ros-args", "-p", f"output:={tmp_path}/r.mcap"] if node == "recorder" else []
    with log.open("w") as handle:
        proc = subprocess.Popen([entry_point(node), *extra], stdout=handle, stderr=subprocess.STDOUT, env=env,
                                start_new_session=True)
        assert wait_for(lambda: handles_stop_signals(proc.pid), timeout=60)
        if node == "line_sim":  # stop it while it simulates, not while it loads
            assert wait_for(lambda: "lanes at" in log.read_text(), timeout=60)
        time.sleep(1.5)
        if sig == "SIGINT":
            os.killpg(proc.pid, signal.SIGINT)
        else:
            proc.send_signal(signal.SIGTERM)
        code = proc.wait(60)
    text = log.read_text()
    assert code == 0, text
    assert "Traceback" not in text and "RuntimeError" not in text and "RCLError" not in text, text
    assert sum(SUMMARIES[node] in line for line in text.splitlines()) == 1, text


@pytest.fixture
def make_node():
    context = rclpy.Context()
    rclpy.init(context=context)
    nodes = []

    def make(**overrides):
        node = rclpy.create_node(f"params_{len(nodes)}", context=context,
                                 parameter_overrides=[Parameter(k, value=v) for k, v in overrides.items()])
        nodes.append(node)
        return node

    yield make
    for node in nodes:
        node.destroy_node()
    rclpy.try_shutdown(context=context)


def test_a_whole_number_for_a_decimal_parameter_is_that_decimal(make_node):
    node = make_node(speed=130, ks=[0, 100])
    assert declare(node, "speed", 100.0, "speed", 1.0, 400.0) == 130.0
    assert isinstance(node.get_parameter("speed").value, float)
    assert declare(node, "ks", [0.0, 100.0], "k values") == [0.0, 100.0]
    assert node.get_parameter("ks").type_ == Parameter.Type.DOUBLE_ARRAY


def test_the_range_still_holds_for_whole_numbers_and_other_types_are_still_refused(make_node):
    with pytest.raises(InvalidParameterValueException):
        declare(make_node(speed=0), "speed", 100.0, "speed", 1.0, 400.0)
    with pytest.raises(InvalidParameterTypeException):
        declare(make_node(speed="fast"), "speed", 100.0, "speed", 1.0, 400.0)
    with pytest.raises(InvalidParameterTypeException):
        declare(make_node(lanes=2.5), "lanes", 3, "lanes", 1, 6)
    assert declare(make_node(speed=2.5), "speed", 100.0, "speed", 1.0, 400.0) == 2.5


def test_a_node_started_with_a_whole_number_speed_runs(ros_domain):
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain))
    command = [entry_point("reject_gate"), "--ros-args", "-p", "line_speed_fpm:=130"]
    with pytest.raises(subprocess.TimeoutExpired):  # still running: not refused
        subprocess.run(command, capture_output=True, timeout=4, env=env)


def test_a_nan_or_infinite_decimal_is_refused_even_without_a_range(make_node):
    with pytest.raises(ValueError, match=r"parameter gaps: must be a finite number, got \[0.6, nan\]"):
        declare(make_node(gaps=[0.6, math.nan]), "gaps", [0.6], "gaps")
    with pytest.raises(ValueError, match="parameter period: must be a finite number, got inf"):
        declare(make_node(period=math.inf), "period", 1.0, "period")
    assert declare(make_node(gaps=[0.5, 0.7]), "gaps", [0.6], "gaps") == [0.5, 0.7]


def test_a_second_stop_signal_during_the_first_never_waits_on_the_stop_event():
    """A parent's death signal and a process-group stop can arrive together; the second handler call runs inside
    the first one's Event.set, whose lock it must not wait for (that deadlocked line_sim for good)."""
    import threading

    from woody_common.ros_params import stop_handler

    stop = threading.Event()
    handler = stop_handler(stop)
    handler(signal.SIGTERM, None)
    assert stop.is_set()
    with stop._cond:  # as if the first call were still inside Event.set, holding its lock
        second = threading.Thread(target=handler, args=(signal.SIGINT, None), daemon=True)
        second.start()
        second.join(timeout=2.0)
        assert not second.is_alive()
