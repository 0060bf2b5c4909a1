"""The vision nodes on a host without the simulator: `segmenter` and `grader` start from a params file with
`woody_sim` and pybullet unimportable, and the grader's calibrated values come from that file alone.

Each node runs in its own process through its entry point's ``main``, behind a meta path finder that
refuses ``woody_sim`` and ``pybullet``; the test reads the running node's parameters back over its
parameter services.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest
import rclpy
import yaml
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient

from woody_common.calibration import ENV_VAR, resolved_calibration

pytestmark = pytest.mark.ros  # starts node processes on a private domain

BLOCKED_START = textwrap.dedent("""
    import sys

    class VisionOnlyHost:
        BLOCKED = ("woody_sim", "pybullet")

        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in self.BLOCKED:
                raise ModuleNotFoundError(f"No module named {name!r} (vision-only host)", name=name)
            return None

    sys.meta_path.insert(0, VisionOnlyHost())
    for name in [m for m in sys.modules if m.split(".")[0] in VisionOnlyHost.BLOCKED]:
        del sys.modules[name]
    entry, module = sys.argv[1], sys.argv[2]
    sys.argv = [entry, *sys.argv[3:]]
    import importlib
    importlib.import_module(module).main()
""")

THRESHOLD = 9.75
CUTS = {"line_threshold": [6.5, -1.0, -0.25, 0.0, 0.0],
        "severe_threshold": [5.0, -1.0, -0.25, 0.0, 0.0], "fitted_range": [0.4, 0.8, 40.0, 0.1, 0.3]}


def parameters(ros_node, domain: int, entry: str, module: str, names: list[str], *args: str,
               env: dict | None = None) -> dict:
    """Start ``entry`` on the vision-only host, read ``names`` from it while it runs, stop it."""
    environment = dict(os.environ if env is None else env, ROS_DOMAIN_ID=str(domain))
    proc = subprocess.Popen([sys.executable, "-c", BLOCKED_START, entry, module, *args], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env=environment, cwd="/tmp")
    try:
        client = AsyncParameterClient(ros_node, entry)
        if not client.wait_for_services(timeout_sec=30.0):
            proc.kill()
            pytest.fail(f"{entry} did not start: {proc.communicate()[0][-2000:]}")
        for _ in range(3):  # a request sent before the node has matched this client's reply reader gets no reply
            future = client.get_parameters(names)
            rclpy.spin_until_future_complete(ros_node, future, SingleThreadedExecutor(context=ros_node.context), 10.0)
            if future.result() is not None:
                return {name: parameter_value_to_python(value) for name, value in zip(names, future.result().values)}
        pytest.fail(f"{entry} answered no parameter request in 30 s")
    finally:
        proc.terminate()
        output = proc.communicate(timeout=30)[0]
        assert proc.returncode == 0, output[-2000:]


def params_file(tmp_path) -> str:
    """A vision host's params file: the grader's calibrated values and the lane count of both nodes."""
    data = {"/**/grader": {"ros__parameters": {"threshold": THRESHOLD, **CUTS, "lanes": 3}},
            "/**/segmenter": {"ros__parameters": {"lanes": 3}}}
    path = tmp_path / "vision.yaml"
    path.write_text(yaml.safe_dump(data))
    return str(path)


def test_the_block_works(ros_domain):
    result = subprocess.run([sys.executable, "-c", BLOCKED_START.replace("importlib.import_module(module).main()",
                                                                         "import woody_sim"), "x", "y"],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode != 0 and "vision-only host" in result.stderr


def test_segmenter_starts_from_a_params_file_without_the_simulator(ros_node, ros_domain, tmp_path):
    values = parameters(ros_node, ros_domain, "segmenter", "woody_vision.segmenter_node", ["lanes"],
                        "--ros-args", "--params-file", params_file(tmp_path))
    assert values == {"lanes": 3}


def test_grader_starts_from_a_params_file_without_the_simulator_or_a_calibration(ros_node, ros_domain, tmp_path):
    env = dict(os.environ, **{ENV_VAR: str(tmp_path / "no-such-calibration.yaml")})  # a read would fail
    values = parameters(ros_node, ros_domain, "grader", "woody_vision.grader_node", ["threshold", *CUTS, "lanes"],
                        "--ros-args", "--params-file", params_file(tmp_path), env=env)
    assert values == {"threshold": THRESHOLD, **CUTS, "lanes": 3}


def test_grader_alone_takes_the_resolved_calibration(ros_node, ros_domain):
    env = {k: v for k, v in os.environ.items() if k != ENV_VAR}
    calibration = resolved_calibration()
    values = parameters(ros_node, ros_domain, "grader", "woody_vision.grader_node", ["threshold", "line_threshold"],
                        env=env)
    assert values == {"threshold": calibration.phi_threshold, "line_threshold": list(calibration.line_threshold)}
