"""Bad parameters as a user types them, through every node's entry point and `woody run`.

A refusal is one line, ``<program>: ...``, exit code 2, no traceback, and nothing claimed: the
command runs in an empty folder that stays empty (the recorder is pointed at a bag in it, `woody
run` at an output folder in it). Unknown names are refused with the names the node knows (the list
its ``--help`` prints, with the values the overrides give); stray arguments print the usage; a NaN,
an empty list or a value outside the range is refused with the same range in every node that takes
the parameter; every parameter is read-only, so setting one on a running node (what ``ros2 param
set`` does) is refused with the reason.

The refusals run as one batch per table, four processes at a time (each takes 1-2 s alone).
More `woody run` refusals (``--k 0 nan``, ``--speed-fpm 0.5``, the line options) are in
tests/woody_tools/test_woody_run.py.
"""

from __future__ import annotations

import re
import signal
import subprocess

import pytest

from bad_input.conftest import assert_one_clear_line, run_entries
from woody_tools.processes import entry_point, lease_domain

pytestmark = pytest.mark.ros
"""Starts node entry points and `woody run` as processes."""

NODES = ("line_sim", "segmenter", "grader", "reject_gate", "recorder")
BAG = "refused.mcap"
"""Where the recorder is told to record in every refused command: it must not be created."""
UNCLOSED = "Couldn't parse parameter override rule: '-p lanes:=['"


def ros_args(node: str, *overrides: str) -> tuple[str, ...]:
    bag = ("-p", f"output:={BAG}") if node == "recorder" else ()
    return (node, "--ros-args", *bag, *(word for override in overrides for word in ("-p", override)))


NODE_REFUSALS = {  # command: what its one line says
    # a typo in a name, a malformed override, a params file that is not there
    **{ros_args(node, "line_sped_fpm:=130"): "invalid parameter: unknown parameter line_sped_fpm; " for node in NODES},
    ("grader", "--help", "--ros-args", "-p", "line_sped_fpm:=130"): "unknown parameter line_sped_fpm; grader knows",
    **{ros_args(node, "lanes:=["): f"bad --ros-args: {UNCLOSED}" for node in NODES},
    **{ros_args(node, "lanes"): "bad --ros-args: Couldn't parse parameter override rule: '-p lanes'" for node in NODES},
    ("line_sim", "--ros-args", "--params-file", "missing.yaml"):
        "bad --ros-args: Couldn't parse params file: '--params-file missing.yaml'",
    # empty, NaN, infinite or mistyped values
    ros_args("line_sim", "k_values:=[]"): "parameter k_values: needs a value like [0.0, 100.0], got an empty",
    ros_args("reject_gate", "gate_distance_m:=[]"): "parameter gate_distance_m: needs a value like [0.6], got an",
    ros_args("grader", "line_threshold:=[]"): "parameter line_threshold: needs a value like [",
    ros_args("line_sim", "k_values:=[0.0, .nan]"): "parameter k_values: must be a finite number, got [0.0, nan]",
    ros_args("reject_gate", "gate_distance_m:=[.nan]"): "parameter gate_distance_m: must be a finite number",
    ros_args("grader", "line_threshold:=[.inf, 0.0, 0.0]"): "parameter line_threshold: must be a finite number",
    ros_args("line_sim", "line_speed_fpm:=.nan"): "Parameter line_speed_fpm out of range Min: 1.0, Max: 400.0",
    ros_args("segmenter", "lanes:=2.5"): "Trying to set parameter 'lanes' to '2.5' of type 'DOUBLE', expecting",
    # out of range: one range for a parameter in every node that takes it
    ros_args("line_sim", "line_speed_fpm:=0.5"): "Parameter line_speed_fpm out of range Min: 1.0, Max: 400.0",
    ros_args("reject_gate", "line_speed_fpm:=0.5"): "Parameter line_speed_fpm out of range Min: 1.0, Max: 400.0",
    ros_args("reject_gate", "line_speed_fpm:=1000"): "Parameter line_speed_fpm out of range Min: 1.0, Max: 400.0",
    **{ros_args(node, "lanes:=7"): "Parameter lanes out of range. Min: 1, Max: 6"
       for node in ("line_sim", "segmenter", "grader", "reject_gate")},
    **{ros_args(node, f"lane_pitch_m:={pitch}"): "Parameter lane_pitch_m out of range Min: 0.08, Max: 1.04"
       for node in ("line_sim", "segmenter") for pitch in (0.05, 1.5)},
    ros_args("line_sim", "k_values:=[-1.0]"): "k_values must be a non-empty list of finite values >= 0, got [-1.0]",
    ros_args("segmenter", "min_area_px:=0"): "Parameter min_area_px out of range. Min: 1, Max: 100000",
    ros_args("grader", "threshold:=-1.0"): "Parameter threshold out of range Min: 0.001, Max: 1000.0",
    ros_args("recorder", "queue_depth:=0"): "Parameter queue_depth out of range. Min: 1, Max: 100000",
    ros_args("recorder", "discovery_period:=.nan"): "Parameter discovery_period out of range Min: 0.01, Max: 60.0",
    ros_args("recorder", "discovery_period:=.inf"): "Parameter discovery_period out of range Min: 0.01, Max: 60.0",
    ros_args("recorder", "flush_period:=.nan"): "Parameter flush_period out of range Min: 0.01, Max: 60.0",
    ros_args("recorder", "flush_period:=0.0"): "Parameter flush_period out of range Min: 0.01, Max: 60.0",
    ros_args("recorder", "compression_level:=23"): "Parameter compression_level out of range. Min: 1, Max: 22",
    ros_args("recorder", "chunk_size:=0"): "Parameter chunk_size out of range. Min: 1, Max: 1073741824",
    ros_args("recorder", "max_buffer_mb:=100000"): "Parameter max_buffer_mb out of range. Min: 1, Max: 65536",
    # names that are not one of the choices
    ros_args("line_sim", "top_camera:=wide"): "unknown top camera preset 'wide'; known: default, paper",
    ros_args("line_sim", "sensor:=lidar"): "unknown sensor 'lidar': choose one of ideal, stereo, structured_light",
    ros_args("line_sim", "line:=muddy"): "unknown line preset 'muddy'",
    ros_args("segmenter", "image_qos:=fast"): "image_qos must be one of sensor_data, reliable, got 'fast'",
    ros_args("recorder", "compression:=bogus"): "unknown compression 'bogus' (zstd, lz4 or none)",
    # values that do not fit together
    ros_args("line_sim", "lane_pitch_m:=0.2", "lanes:=6"): "need a 1.360 m belt",
    ros_args("line_sim", "lateral_max_m:=0.045", "lane_pitch_m:=0.08"): "at most half the lane pitch",
    ros_args("line_sim", "fillets_per_minute:=250.0"): "at most 203 per minute",
    ros_args("line_sim", "spawn_spacing_m:=0.1"): "spawn_spacing_m",
    ros_args("line_sim", "speed_change_fpm:=0.5"): "speed_change_fpm must be 0 or within 1..400",
    ros_args("line_sim", "scale_min:=1.3"): "scale_max must be >= scale_min 1.3",
    ros_args("line_sim", "physics_workers:=0", "physics_recycle_fillets:=300"):
        "physics_recycle_fillets needs physics_workers >= 1",
    ros_args("line_sim", "top_camera_mount:=[0.0, 0.0, 0.75, 0.0, 0.0, 0.0, 2.0]"):
        "top_camera_mount must be [x, y, z, qx, qy, qz, qw] with a unit quaternion",
    ros_args("grader", "side_lane:=4"): "side_lane 4 is not a lane (0..2)",
    ros_args("reject_gate", "gate_distance_m:=[0.5, 0.6]"): "gate_distance_m needs 1 or 3 values, got 2",
}
RUN_REFUSALS = {  # `woody run` options that become node parameters: refused before any node starts
    ("--lanes", "7"): "--lanes must be 1..6, got 7",
    ("--lanes", "0"): "--lanes must be 1..6, got 0",
    ("--speed-fpm", "400.5"): "--speed-fpm must be in [1, 400], got 400.5",
    ("--speed-fpm", "nan"): "--speed-fpm must be in [1, 400], got nan",
    ("--k", "-1"): "--k values must be finite and >= 0, got -1",
    ("--k", "0", "inf"): "--k values must be finite and >= 0, got 0 inf",
    ("--fillets", "0"): "--fillets must be 1..100000, got 0",
    ("--fillets", "200000"): "--fillets must be 1..100000, got 200000",
    ("--seed", "-1"): "--seed must be 0..2147483647, got -1",
    ("--seed", "3000000000"): "--seed must be 0..2147483647, got 3000000000",
    ("--score", "paper", "--threshold", "0.0005"): "--threshold must be in [0.001, 1000], got 0.0005",
    ("--side-rate", "-1"): "--side-rate must be in [0, 400] Hz (0: no side camera), got -1",
}


CONFIGURED_HELP = ("reject_gate", "--help", "--ros-args", "-p", "line_speed_fpm:=130", "-p", "lanes:=2")
"""``--help`` with overrides describes the node as they configure it."""


@pytest.fixture(scope="module")
def domain():
    with lease_domain({}) as lease:
        yield lease.domain_id


@pytest.fixture(scope="module")
def refused(domain) -> dict:
    """Every command of both tables and every node's ``--help`` and stray argument, run once."""
    commands = [*NODE_REFUSALS, *((node, "--help") for node in NODES), *((node, "--lanes", "3") for node in NODES),
                CONFIGURED_HELP]
    outcomes = run_entries(commands, domain, timeout=120)  # four at a time on two cores, each importing pybullet
    runs = [("woody", "run", "--fillets", "1", "--out", "run", *options) for options in RUN_REFUSALS]
    outcomes += run_entries(runs, None, timeout=60)
    return dict(zip([*commands, *RUN_REFUSALS], outcomes))


@pytest.mark.parametrize("command", list(NODE_REFUSALS), ids=" ".join)
def test_a_bad_parameter_is_one_line_and_exit_2(refused, command):
    outcome = refused[command]
    assert_one_clear_line(outcome, command[0], NODE_REFUSALS[command])
    assert not any(outcome.cwd.iterdir()), list(outcome.cwd.iterdir())  # no bag, no log, nothing claimed


@pytest.mark.parametrize("options", list(RUN_REFUSALS), ids=" ".join)
def test_a_bad_run_option_is_one_line_before_any_node_starts(refused, options):
    outcome = refused[options]
    assert_one_clear_line(outcome, "woody run", RUN_REFUSALS[options])
    assert not any(outcome.cwd.iterdir()), list(outcome.cwd.iterdir())  # no output folder


RCLPY_OWN = {"use_sim_time", "start_type_description_service"}
"""Parameters rclpy declares on every node."""


@pytest.mark.parametrize("node", NODES)
def test_an_unknown_name_is_refused_with_the_names_help_lists(refused, node):
    line = refused[ros_args(node, "line_sped_fpm:=130")].lines[0]
    known = set(line.split(f"{node} knows: ")[1].split(", ")) - RCLPY_OWN
    shown = refused[(node, "--help")]
    assert shown.code == 0 and shown.stdout.startswith(f"usage: {node} [--ros-args "), shown.lines
    assert len(known) > 4 and {name for name in known if not re.search(rf"\b{name}\b", shown.stdout)} == set()


def test_help_with_overrides_shows_the_values_they_give(refused):
    outcome = refused[CONFIGURED_HELP]
    assert outcome.code == 0, outcome.lines
    assert "\n  line_speed_fpm = 130.0 [1, 400]: " in outcome.stdout and "\n  lanes = 2 [1, 6]: " in outcome.stdout


@pytest.mark.parametrize("node", NODES)
def test_a_stray_argument_prints_the_usage_and_exit_2(refused, node):
    outcome = refused[(node, "--lanes", "3")]
    assert outcome.code == 2 and "Traceback" not in outcome.stderr
    assert outcome.lines[0] == f"{node}: unexpected argument --lanes 3", outcome.lines
    assert outcome.lines[1].startswith(f"usage: {node} [--ros-args -p name:=value ... | --params-file FILE]")
    assert f"`{node} --help` lists its parameters" in outcome.lines[2]


RUNTIME_SETS = {"line_sim": ("line_speed_fpm", 130.0), "segmenter": ("lanes", 4), "grader": ("threshold", 9.0),
                "reject_gate": ("line_speed_fpm", 130.0), "recorder": ("output", "elsewhere.mcap")}
"""A parameter of each node set at runtime, as `ros2 param set <node> <name> <value>` would."""


@pytest.fixture
def running_nodes(ros_domain, tmp_path):
    """Every node started from its entry point in tmp_path (line_sim held until a camera subscriber comes)."""
    import os

    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain), PYTHONUNBUFFERED="1")
    extra = {"line_sim": ("-p", "wait_for_subscribers:=1"), "recorder": ("-p", f"output:={BAG}")}
    procs = {}
    for node in NODES:
        log = open(tmp_path / f"{node}.log", "w")
        procs[node] = subprocess.Popen([entry_point(node), "--ros-args", *extra.get(node, ())], cwd=tmp_path, env=env,
                                       stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        log.close()
    yield procs
    for proc in procs.values():
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_a_parameter_set_on_a_running_node_is_refused_as_read_only(ros_node, running_nodes, tmp_path):
    """Each node keeps its value and says why; then it stops with its summary and the bag is readable."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient

    from woody_bag.summary import bag_summary

    executor = SingleThreadedExecutor(context=ros_node.context)
    executor.add_node(ros_node)

    def answer(future):
        executor.spin_until_future_complete(future, timeout_sec=30)
        assert future.done()
        return future.result()

    try:
        for node, (name, value) in RUNTIME_SETS.items():
            client = AsyncParameterClient(ros_node, node)
            assert client.wait_for_services(timeout_sec=60), f"{node} offers no parameter service"
            before = answer(client.get_parameters([name])).values
            result = answer(client.set_parameters([Parameter(name, value=value)])).results[0]
            assert not result.successful and result.reason == f"Trying to set a read-only parameter: {name}.", node
            assert answer(client.get_parameters([name])).values == before, node
    finally:
        executor.shutdown()
    for proc in running_nodes.values():
        proc.send_signal(signal.SIGINT)
    for node, proc in running_nodes.items():
        assert proc.wait(60) == 0 and "Traceback" not in (tmp_path / f"{node}.log").read_text(), node
    assert bag_summary(tmp_path / BAG) is not None and not (tmp_path / "elsewhere.mcap").exists()
