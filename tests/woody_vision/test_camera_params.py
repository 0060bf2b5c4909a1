"""The example parameter files for common cameras (config/cameras/params/*.yaml) load into the vision nodes: every
value is a declared parameter, in range, and taken as written."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
import yaml

from woody_tools.processes import entry_point

pytestmark = pytest.mark.ros
CAMERAS = Path(__file__).resolve().parents[2] / "config" / "cameras"


@pytest.mark.parametrize("path", sorted((CAMERAS / "params").glob("*.yaml")), ids=lambda p: p.name)
@pytest.mark.parametrize("node", ["segmenter", "grader"])
def test_an_example_parameter_file_sets_the_nodes_parameters_as_written(path, node):
    values = yaml.safe_load(path.read_text())[f"/**/{node}"]["ros__parameters"]
    shown = subprocess.run([entry_point(node), "--help", "--ros-args", "--params-file", str(path)],
                           capture_output=True, text=True, timeout=120)
    assert shown.returncode == 0, shown.stderr[-2000:]
    for name, value in values.items():
        assert f"  {name} = {value!r}" in shown.stdout or f"  {name} = {value} " in shown.stdout, name
