"""Declared parameters: whole numbers for decimal parameters, ranges still enforced."""

from __future__ import annotations

import os
import subprocess

import pytest
import rclpy
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.parameter import Parameter

from woody_sim.ros_params import declare
from woody_tools.graph import entry_point


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


def test_a_node_started_with_a_whole_number_speed_runs_and_one_out_of_range_exits_with_one_line(ros_domain):
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain))
    command = [entry_point("reject_gate"), "--ros-args", "-p", "line_speed_fpm:=130"]
    with pytest.raises(subprocess.TimeoutExpired):
        subprocess.run(command, capture_output=True, timeout=4, env=env)
    result = subprocess.run([*command[:-1], "line_speed_fpm:=1000"], capture_output=True, text=True, timeout=30,
                            env=env)
    assert result.returncode == 2 and "out of range" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
