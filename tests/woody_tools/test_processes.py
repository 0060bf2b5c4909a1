"""Starting nodes: parameters become a params file, namespaces the right --ros-args."""

from __future__ import annotations

from woody_tools.processes import namespace_args, write_params_file


def test_a_namespace_moves_the_node_and_gives_it_its_own_clock():
    assert namespace_args("") == []
    for ns in ("line2", "/line2", "/line2/"):
        assert namespace_args(ns) == ["-r", "__ns:=/line2", "-r", "/clock:=/line2/clock"]


def test_parameters_go_to_a_params_file_unchanged(tmp_path):
    import yaml

    params = {"lanes": 3, "speed": 130.0, "realtime": False, "k": [0.0, 100.0], "output": "/tmp/run #1: x/line.mcap"}
    path = write_params_file(tmp_path / "p.yaml", params)
    assert yaml.safe_load(path.read_text()) == {"/**": {"ros__parameters": params}}
