"""Starting nodes: parameters and namespaces become the right --ros-args."""

from __future__ import annotations

from woody_tools.graph import namespace_args, ros_args


def test_a_namespace_moves_the_node_and_gives_it_its_own_clock():
    assert namespace_args("") == []
    for ns in ("line2", "/line2", "/line2/"):
        assert namespace_args(ns) == ["-r", "__ns:=/line2", "-r", "/clock:=/line2/clock"]


def test_parameters_become_ros_args():
    assert ros_args({"lanes": 3, "speed": 130.0, "realtime": False, "k": [0.0, 100.0], "meshes": ""}) == [
        "--ros-args", "-p", "lanes:=3", "-p", "speed:=130.0", "-p", "realtime:=false", "-p", "k:=[0.0,100.0]",
        "-p", "meshes:=''"]
