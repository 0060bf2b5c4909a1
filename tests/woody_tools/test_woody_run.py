"""`woody run` end to end: bag, verdict table and report; a node that dies stops the run and the bag survives."""

from __future__ import annotations

import csv
import json
import os
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest
import yaml
from fixtures.rosbag2_conformance import assert_rosbag2_conformant, clock_span_ns

from woody_tools.line_run import RunRefused
from woody_tools.processes import entry_point, lease_domain

pytestmark = pytest.mark.ros
"""Starts node entry points or `woody` as processes."""


def _bag_messages(path):
    from woody_bag.summary import bag_summary

    return bag_summary(path)


def test_woody_run_leaves_bag_table_and_report(tmp_path):
    """Run in a namespace, as one of several lines in a domain would: everything lives under it."""
    out = tmp_path / "run"
    result = subprocess.run([entry_point("woody"), "run", "--fillets", "3", "--k", "0", "100", "--seed", "3",
                             "--out", str(out), "--namespace", "line2"], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    rows = list(csv.DictReader((out / "verdicts.csv").open()))
    assert len(rows) == 3 and {r["lane"] for r in rows} == {"0", "1", "2"}
    assert all(r["verdict"] in ("normal", "woody") and r["truth"] in ("normal", "woody") for r in rows)
    assert list(rows[0])[:12] == ["fillet_id", "lane", "mesh", "k", "speed_fpm", "phi", "hu_term", "solidity_term",
                                  "nmdm", "mdm", "be", "verdict"]
    report = (out / "report.md").read_text()
    assert "accuracy" in report and "Φ" in report
    for png in ("phi_by_k_lane.png", "nmdm_by_k.png", "confusion.png"):
        assert (out / png).stat().st_size > 1000
    summary = _bag_messages(out / "line.mcap")
    assert summary["complete"], summary
    counts = {topic: info["count"] for topic, info in summary["topics"].items()}
    assert all(topic.startswith("/line2/") for topic in counts), sorted(counts)
    assert counts["/line2/grading/verdicts"] == 3 and counts["/line2/line/ground_truth"] == 3
    assert counts["/line2/top_camera/depth/image_raw"] > 30 and counts["/line2/clock"] > 100
    messages = assert_rosbag2_conformant(out / "line.mcap")
    first_clock, last_clock = clock_span_ns(out / "line.mcap", "/line2/clock")
    assert 0 <= messages[0].log_time <= first_clock + 10**9  # the line's sim time, not the wall clock
    assert last_clock <= messages[-1].log_time <= last_clock + 10**9
    assert "fillet_id" in result.stdout and str(out / "line.mcap") in result.stdout
    # the line's own pace, from its first /clock, apart from the nodes' start-up
    assert re.search(r"\nthe line itself, after \d+\.\d s of node start-up: rtf \d+\.\d\dx\n", result.stdout)
    report = subprocess.run([entry_point("woody"), "report", str(out / "line.mcap"), "--out", str(tmp_path / "again")],
                            capture_output=True, text=True, timeout=120)
    assert report.returncode == 0, report.stderr  # the namespaced bag's verdicts and ground truth are found
    again = list(csv.DictReader((tmp_path / "again" / "verdicts.csv").open()))
    verdict = ["fillet_id", "lane", "verdict", "score", "reason", "truth"]  # the table is the bag's verdicts
    assert [[r[c] for c in verdict] for r in again] == [[r[c] for c in verdict] for r in rows]


def test_a_plant_camera_is_rendered_as_its_file_describes_and_the_vision_grades_through_it(tmp_path):
    """An Orbbec-class camera: tilted, rolled, turned, beside the belt's middle, with barrel distortion, colour
    stamps 8 ms after depth and a structured-light error model. The bag carries its lens and pose; the segmenter
    resamples its frames into the belt view and every fillet gets its right verdict."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    camera = Path(__file__).resolve().parents[2] / "config" / "cameras" / "orbbec-femto.yaml"
    out = tmp_path / "run"
    result = woody_run("--fillets", "6", "--k", "0", "100", "--seed", "5", "--top-camera", str(camera), "--out",
                       str(out), timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    rows = list(csv.DictReader((out / "verdicts.csv").open()))
    assert len(rows) == 6 and all(r["verdict"] == r["truth"] for r in rows), rows
    assert "resampled into the belt view" in (out / "logs" / "segmenter.log").read_text()
    assert "cuts were fitted on the 'default' top camera, not this run's 'orbbec-femto'" in result.stderr
    with (out / "line.mcap").open("rb") as f:
        messages = make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
            topics=["/top_camera/depth/camera_info", "/tf_static"])
        first = {}
        for _, channel, _, msg in messages:
            first.setdefault(channel.topic, msg)
    info, tf = first["/top_camera/depth/camera_info"], first["/tf_static"]
    assert info.distortion_model == "rational_polynomial" and list(info.d)[0] == pytest.approx(0.45)
    (top,) = [t for t in tf.transforms if t.child_frame_id == "top_camera_optical_frame"]
    assert (top.transform.translation.y, top.transform.translation.z) == pytest.approx((-0.05, 0.70))
    # set the vision up from that recording alone: the mount and the line the camera file describes
    params = tmp_path / "setup" / "params.yaml"
    setup = subprocess.run([entry_point("woody"), "camera", "setup", str(out / "line.mcap"), "--out", str(params)],
                           capture_output=True, text=True, timeout=300)
    assert setup.returncode == 0, setup.stderr[-2000:]
    found = yaml.safe_load(params.read_text())
    grader, segmenter = found["/**/grader"]["ros__parameters"], found["/**/segmenter"]["ros__parameters"]
    assert grader["lanes"] == segmenter["lanes"] == 3 and segmenter["lane_pitch_m"] == pytest.approx(0.16, abs=0.005)
    assert grader["camera_height_m"] == pytest.approx(0.70, abs=0.005)
    assert grader["roller_edge_offset_m"] == pytest.approx(0.18, abs=0.005)
    tilt, roll, yaw = (float(v) for v in re.search(r"tilt ([-+.\d]+) deg .* roll ([-+.\d]+) deg .* yaw ([-+.\d]+) deg",
                                                   setup.stdout).groups())
    assert (tilt, roll, yaw) == pytest.approx((5.0, 3.0, -2.0), abs=0.5)
    assert params.with_suffix(".png").stat().st_size > 1000
    # and grade through that setup alone: the line puts the found mount on tf_static, not the camera's own
    again = tmp_path / "again"
    result = woody_run("--fillets", "6", "--k", "0", "100", "--seed", "5", "--top-camera", str(camera),
                       "--vision-setup", str(params), "--out", str(again), timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    rows = list(csv.DictReader((again / "verdicts.csv").open()))
    assert len(rows) == 6 and all(r["verdict"] == r["truth"] for r in rows), rows
    mount = found["/**/line_sim"]["ros__parameters"]["top_camera_mount"]
    with (again / "line.mcap").open("rb") as f:
        tf = next(msg for _, _, _, msg in make_reader(f, decoder_factories=[DecoderFactory()])
                  .iter_decoded_messages(topics=["/tf_static"]))
    (top,) = [t for t in tf.transforms if t.child_frame_id == "top_camera_optical_frame"]
    t, q = top.transform.translation, top.transform.rotation
    assert [t.x, t.y, t.z, q.x, q.y, q.z, q.w] == pytest.approx(mount, abs=1e-5)


def test_outside_the_calibrated_speeds_no_woody_fillet_is_graded_normal(tmp_path):
    out = tmp_path / "run"
    result = subprocess.run([entry_point("woody"), "run", "--fillets", "3", "--k", "100", "--speed-fpm", "400",
                             "--gate-distance", "1.0", "--out", str(out)], capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    note = "line speed 400 FPM is outside the 90..140 FPM the calibration's cuts were fitted on: fillets measured"
    assert note in result.stderr and note in (out / "report.md").read_text()
    rows = list(csv.DictReader((out / "verdicts.csv").open()))
    assert len(rows) == 3 and {r["verdict"] for r in rows} == {"unscored"}, [(r["verdict"], r["reason"]) for r in rows]
    assert all(r["reason"].startswith("outside the calibration: measured speed") for r in rows)


def test_a_dying_node_stops_the_run_and_the_bag_is_finalised(tmp_path):
    out = tmp_path / "run"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    run = subprocess.Popen([entry_point("woody"), "run", "--fillets", "30", "--out", str(out)],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    log = out / "logs" / "reject_gate.log"  # a fillet graded: the run has something to keep
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline and "divert fillet" not in (log.read_text() if log.exists() else ""):
        time.sleep(0.2)
    pids = subprocess.run(["pgrep", "-f", "bin/segmenter --ros-args"], capture_output=True, text=True).stdout.split()
    mine = [p for p in pids if str(out) in _parent_cmdline(p)]
    assert mine, f"segmenter of this run not found among {pids}"
    os.kill(int(mine[0]), signal.SIGKILL)
    stdout, stderr = run.communicate(timeout=120)
    assert run.returncode == 1
    assert "node 'segmenter' exited" in stderr and (out / "verdicts.csv").exists()
    summary = _bag_messages(out / "line.mcap")
    assert summary["complete"] and summary["topics"]["/top_camera/depth/image_raw"]["count"] > 0


def _parent_cmdline(pid: str) -> str:
    ppid = open(f"/proc/{pid}/stat").read().split(")")[1].split()[1]
    return open(f"/proc/{ppid}/cmdline", "rb").read().replace(b"\0", b" ").decode(errors="replace")


# ---------------------------------------------------------------- bad input: one line, exit 2, nothing lost

def woody_run(*args: str, env: dict | None = None, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([entry_point("woody"), "run", *args], capture_output=True, text=True, timeout=timeout,
                          env=env)


@pytest.fixture
def other_run_holds(tmp_path):
    """Play the part of another `woody run`: hold its --out folder lock or its exported domain's lease."""
    import fcntl

    held = []

    def hold(kind: str, value: str):
        if kind == "out":
            Path(value).mkdir(parents=True, exist_ok=True)
            handle = open(Path(value) / ".woody-run.lock", "w")
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            held.append(handle)
        else:  # a free domain, held the way a running `woody run` holds it
            held.append(lease_domain({}))
            return held[-1].domain_id

    yield hold
    for item in held:
        item.close() if hasattr(item, "close") else item.release()


@pytest.mark.parametrize("setup,args,message", [
    (None, ["--k", "0", "nan"], "--k values must be finite and >= 0, got 0 nan"),
    (None, ["--speed-fpm", "0.5"], "--speed-fpm must be in [1, 400], got 0.5"),
    (None, ["--duration", "-1"], "--duration must be in (0, 1e+06] sim seconds, got -1"),
    (None, ["--side-rate", "500"], "--side-rate must be in [0, 400] Hz (0: no side camera), got 500"),
    (None, ["--out", "/proc/woody/run"], "--out /proc/woody/run: cannot write there"),
    ("existing", ["--out", "{tmp}/run"], "already holds a run (line.mcap); pass --force"),
    ("locked", ["--out", "{tmp}/run"], "is in use by another woody run"),
    ("domain", ["--out", "{tmp}/run"], "ROS_DOMAIN_ID={domain} (exported) is in use by another woody run"),
    ("garbage", ["--meshes", "{tmp}/meshes"], "no loadable mesh ({tmp}/meshes/a.stl: not a valid STL"),
    (None, ["--meshes", "generated:x"], "--meshes: mesh spec 'generated:x'"),
])
def test_bad_run_input_is_refused_with_one_line(tmp_path, other_run_holds, setup, args, message):
    env = dict(os.environ)
    if setup == "existing":
        (tmp_path / "run").mkdir()
        (tmp_path / "run" / "line.mcap").write_bytes(b"a recording worth keeping")
    elif setup == "locked":
        other_run_holds("out", str(tmp_path / "run"))
    elif setup == "domain":
        env["ROS_DOMAIN_ID"] = str(other_run_holds("domain", ""))
    elif setup == "garbage":
        (tmp_path / "meshes").mkdir()
        (tmp_path / "meshes" / "a.stl").write_bytes(bytes(300))
    args = args if "--out" in args else [*args, "--out", "{tmp}/default"]
    count = [] if "--duration" in args else ["--fillets", "1"]
    result = woody_run(*count, *[a.format(tmp=tmp_path) for a in args], env=env)
    assert result.returncode == 2, result.stderr
    lines = [line for line in result.stderr.splitlines() if not line.startswith("pybullet build time")]
    expected = message.format(tmp=tmp_path, domain=env.get("ROS_DOMAIN_ID"))
    assert len(lines) == 1 and lines[0].startswith("woody run: ") and expected in lines[0], lines
    if setup == "existing":
        assert (tmp_path / "run" / "line.mcap").read_bytes() == b"a recording worth keeping"
    assert not (tmp_path / "default").exists()  # a refused run writes nothing


def test_awkward_paths_mesh_problems_and_settings_survive_a_run(tmp_path):
    """A folder with '#' and ': ' in its name, an exported ROS_DOMAIN_ID, a scan in mm and a broken STL:
    the bag lands where it was asked to, every skipped or converted mesh is named in the terminal and the
    report, every node closes with its summary and no traceback, and `woody report BAG` rebuilds the
    settings table from the bag alone."""
    import trimesh

    from woody_bag.summary import bag_metadata
    from woody_sim.meshes import BUILTIN_DIR

    meshes = tmp_path / "scans"
    meshes.mkdir()
    raw = trimesh.load(BUILTIN_DIR / "seed0001.obj", force="mesh", process=False)
    trimesh.Trimesh(raw.vertices * 1000.0, raw.faces, process=False).export(meshes / "scan_mm.stl")
    (meshes / "broken.stl").write_bytes(bytes(1000))
    out = tmp_path / "run #1: line"
    with lease_domain({}) as lease:  # free now; exported below as a user's .bashrc would
        domain = lease.domain_id
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    result = woody_run("--fillets", "3", "--meshes", str(meshes), "--out", str(out), env=env, timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    for text in (result.stdout, (out / "report.md").read_text()):
        assert f"skipped mesh {meshes / 'broken.stl'}: not a valid STL" in text
        assert f"converted mesh {meshes / 'scan_mm.stl'}: " in text and "taken as mm" in text
    assert f"bag: {out / 'line.mcap'} (" in result.stdout and f"ROS_DOMAIN_ID={domain}," in result.stdout
    logs = {log.stem: log.read_text() for log in (out / "logs").glob("*.log")}
    summaries = {"line_sim": "stopped at sim time", "segmenter": "depth frames received",
                 "grader": "published 3 verdicts", "reject_gate": "[reject_gate] diverted", "recorder": "MB on disk"}
    for node, summary in summaries.items():
        assert "Traceback" not in logs[node] and logs[node].count(summary) == 1, (node, logs[node][-2000:])
    assert "written/published per topic: /clock " in logs["recorder"]
    settings = json.loads(bag_metadata(out / "line.mcap")["woody"]["run_settings"])
    assert settings["meshes"] == str(meshes) and settings["fillets requested"] == 3

    again = subprocess.run([entry_point("woody"), "report", str(out / "line.mcap"), "--out", str(tmp_path / "re")],
                           capture_output=True, text=True, timeout=120)
    assert again.returncode == 0, again.stderr
    rebuilt = (tmp_path / "re" / "report.md").read_text()
    assert f"| meshes | {meshes} |" in rebuilt and "| fillets spawned | 3 |" in rebuilt
    assert woody_run("--fillets", "1", "--out", str(out)).returncode == 2  # never overwritten without --force


def test_a_run_on_an_exported_domain_with_other_nodes_refuses(tmp_path):
    """Another program (not a woody run, so no lock) already on the user's ROS_DOMAIN_ID: refused, nothing written."""
    import rclpy

    with lease_domain({}) as lease:  # a domain no test uses, then unlocked as a user's domain would be
        ros_domain = lease.domain_id
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=ros_domain)
    node = rclpy.create_node("someone_elses_node", context=context)
    try:
        env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain))
        result = woody_run("--fillets", "1", "--out", str(tmp_path / "run"), env=env)
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    assert result.returncode == 2
    lines = [line for line in result.stderr.splitlines() if not line.startswith("pybullet build time")]
    assert len(lines) == 1 and "already has nodes (/someone_elses_node)" in lines[0], lines
    assert not (tmp_path / "run").exists()


# ---------------------------------------------------------------- a messy, crowded line: options reach the nodes

@pytest.mark.parametrize("args,message", [
    (["--line", "wobbly"], "--line must be one of tidy|messy, got 'wobbly'"),
    (["--yaw-sd", "50"], "--yaw-sd must be within 0..45 deg, got 50"),
    (["--yaw-max", "nan"], "--yaw-max must be within 0..45 deg, got nan"),
    (["--blunt-fraction", "1.5"], "--blunt-fraction must be within 0..1, got 1.5"),
    (["--lateral-sd", "0.06"], "--lateral-sd must be within 0..0.05 m, got 0.06"),
    (["--scale", "0.9"], "--scale must be MIN,MAX with 0.5 <= MIN <= MAX <= 1.5, got '0.9'"),
    (["--scale", "1.2,0.9"], "--scale must be MIN,MAX with 0.5 <= MIN <= MAX <= 1.5, got '1.2,0.9'"),
    (["--lane-pitch", "0.05"], "--lane-pitch: lane pitch must be at least 0.08 m, got 0.05"),
    (["--lanes", "6", "--lane-pitch", "0.2"], "use a lane pitch of at most 0.173 m"),
    (["--lane-pitch", "0.08", "--lateral-max", "0.05"], "--lateral-max at most 0.04 m"),
    (["--spacing", "0.1"], "--spacing must be within 0.15..10 m"),
    (["--spacing", "0.3", "--fillets-per-minute", "100"], "--spacing and --fillets-per-minute both set"),
    (["--fillets-per-minute", "250"], "--fillets-per-minute must be in (0, 203.2] at 100 FPM"),
    (["--speed-fpm", "130", "--fillets-per-minute", "250", "--speed-change", "100@5"],
     "--fillets-per-minute must be in (0, 203.2] at 100 FPM"),  # the rate must hold after the change too
    (["--speed-change", "100"], "--speed-change: expected FPM@SECONDS"),
    (["--speed-change", "500@3"], "--speed-change: expected FPM@SECONDS with FPM in [1, 400]"),
    (["--score", "both"], "--score must be one of line|paper, got 'both'"),
    (["--threshold", "0"], "--threshold must be in [0.001, 1000], got 0"),
    (["--top-camera", "wide"], "--top-camera: unknown top camera preset 'wide'"),
    (["--top-camera", "/nonexistent/mine.yaml"], "--top-camera: camera file /nonexistent/mine.yaml: cannot read it"),
    (["--vision-setup", "/nonexistent/params.yaml"], "--vision-setup /nonexistent/params.yaml: not a woody camera "
                                                     "setup parameters file"),
    (["--physics-workers", "-1"], "--physics-workers must be 0.."),
    (["--physics-recycle", "0"], "--physics-recycle must be >= 1 fillets, got 0"),
    (["--physics-workers", "0", "--physics-recycle", "300"], "--physics-recycle needs --physics-workers >= 1"),
])
def test_bad_line_options_are_refused_before_any_node_starts(tmp_path, args, message):
    result = woody_run("--fillets", "1", "--out", str(tmp_path / "run"), *args, timeout=60)
    lines = [line for line in result.stderr.splitlines() if not line.startswith("pybullet build time")]
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert lines[0].startswith("woody run: ") and message in lines[0], lines
    assert not (tmp_path / "run").exists()


def _parameters(*argv: str) -> dict[str, dict]:
    from woody_tools.cli import build_parser
    from woody_tools.commands.run import checked
    from woody_tools.line_run import node_parameters

    args = checked(build_parser("run").parse_args(["run", *argv]))
    return node_parameters(args, 12, Path("/tmp/unused"))


def test_a_messy_crowded_line_reaches_line_sim_segmenter_and_grader():
    params = _parameters("--lanes", "6", "--speed-fpm", "130", "--line", "messy", "--yaw-sd", "10",
                         "--scale", "0.9,1.1", "--lane-pitch", "0.12", "--spacing", "0.24",
                         "--speed-change", "90@4", "--threshold", "8.5")
    sim = params["line_sim"]
    assert sim["line"] == "messy" and sim["yaw_sd_deg"] == 10.0 and "blunt_fraction" not in sim  # the preset's
    assert (sim["scale_min"], sim["scale_max"], sim["spawn_spacing_m"]) == (0.9, 1.1, 0.24)
    assert (sim["speed_change_fpm"], sim["speed_change_at_s"], sim["line_speed_fpm"]) == (90.0, 4.0, 130.0)
    assert sim["lane_pitch_m"] == params["segmenter"]["lane_pitch_m"] == 0.12
    assert params["grader"]["line_threshold"] == [8.5, 0.0, 0.0, 0.0, 0.0] and "threshold" not in params["grader"]
    assert params["reject_gate"]["divert_unscored"] is True
    settings = json.loads(params["recorder"]["run_settings"])
    assert settings["line conditions"].startswith("messy: yaw sd 10 deg (max 35), 0.5 blunt end first")
    assert settings["speed change"] == "to 90 FPM at 4 s" and settings["unscored fillets diverted"] is True


def test_defaults_keep_the_tidy_line_and_a_paper_threshold_goes_to_the_paper_rule():
    params = _parameters("--fillets-per-minute", "145", "--score", "paper", "--threshold", "11")
    sim = params["line_sim"]
    assert sim["line"] == "tidy" and sim["fillets_per_minute"] == 145.0 and "spawn_spacing_m" not in sim
    assert "speed_change_fpm" not in sim and sim["lane_pitch_m"] == params["segmenter"]["lane_pitch_m"] == 0.16
    assert params["grader"]["score"] == "paper" and params["grader"]["threshold"] == 11.0
    assert "line_threshold" not in params["grader"]
    for speed in ("90", "140"):  # any speed of a real line
        assert _parameters("--speed-fpm", speed)["line_sim"]["line_speed_fpm"] == float(speed)


def test_the_physics_options_reach_line_sim_and_its_defaults_stay_its_own():
    sim = _parameters("--physics-workers", "1", "--physics-recycle", "300", "--paper-physics")["line_sim"]
    assert (sim["physics_workers"], sim["physics_recycle_fillets"]) == (1, 300)
    assert (sim["segments"], sim["physics_rate_hz"]) == (40, 480.0)
    from woody_tools.cli import build_parser
    from woody_tools.commands.run import checked
    from woody_tools.line_run import run_settings

    args = checked(build_parser("run").parse_args(["run", "--physics-workers", "2", "--paper-physics"]))
    assert run_settings(args, 12)["physics"] == "physics_workers 2, segments 40, physics_rate_hz 480"
    assert not {"physics_workers", "physics_recycle_fillets", "segments", "physics_rate_hz"} & set(
        _parameters()["line_sim"])


SETUP = {"/**/segmenter": {"ros__parameters": {"lanes": 3, "camera_height_m": 0.701, "lane_pitch_m": 0.159,
                                               "depth_unit_m": 0.001}},
         "/**/grader": {"ros__parameters": {"lanes": 3, "camera_height_m": 0.701, "roller_edge_offset_m": 0.182}},
         "/**/line_sim": {"ros__parameters": {"top_camera_mount": [-0.18, -0.05, 0.7, 0.718, 0.694, 0.05, 0.012]}}}


def test_a_camera_setup_replaces_the_simulators_own_values_for_the_vision_and_the_published_mount(tmp_path):
    setup = tmp_path / "params.yaml"
    setup.write_text(yaml.safe_dump(SETUP))
    params = _parameters("--vision-setup", str(setup))
    assert params["segmenter"]["camera_height_m"] == 0.701 and params["segmenter"]["lane_pitch_m"] == 0.159
    assert params["grader"]["roller_edge_offset_m"] == 0.182
    assert params["line_sim"]["top_camera_mount"] == SETUP["/**/line_sim"]["ros__parameters"]["top_camera_mount"]
    with pytest.raises(RunRefused, match="found 3 lanes; the line has --lanes 6"):
        _parameters("--vision-setup", str(setup), "--lanes", "6")


def test_a_camera_file_sets_line_sims_camera_its_error_model_and_the_segmenters_depth_unit():
    orbbec = Path(__file__).resolve().parents[2] / "config" / "cameras" / "orbbec-femto.yaml"
    params = _parameters("--top-camera", str(orbbec))
    assert params["line_sim"]["top_camera"] == str(orbbec) and params["line_sim"]["sensor"] == "structured_light"
    assert params["segmenter"]["depth_unit_m"] == 0.001 and params["segmenter"]["camera_height_m"] == 0.7
    assert params["segmenter"]["color_threshold"] > 0  # a real camera's filters
    assert _parameters("--top-camera", str(orbbec), "--sensor", "ideal")["line_sim"]["sensor"] == "ideal"


def test_a_run_whose_grader_is_behind_the_line_waits_for_what_it_owes():
    """The line runs on while a held-up grader works through its queue: the run ends on the grader's progress,
    not on the line's sim time, or the verdicts still in the queue would be lost."""
    from types import SimpleNamespace

    from woody_experiments.run_report import Spawn
    from woody_tools.line_run import LineMonitor, _finished

    spawns = [Spawn(i, 0, "m", 0.0, 1.0, 0.5, 0.0, -1.0) for i in range(2)]  # both cross the roller edge at 2 s
    one_verdict = [SimpleNamespace(fillet_id=0, lane=0)]
    monitor = SimpleNamespace(spawns=spawns, verdicts=one_verdict, sides=[], sim_time=30.0, graded_up_to=None)
    monitor.graded_time = lambda: LineMonitor.graded_time(monitor)
    args = SimpleNamespace(lanes=3, side_rate=0.0, duration=None)
    assert _finished(monitor, 2, args)  # no report from the grader: the line's time
    monitor.graded_up_to = 5.9
    assert not _finished(monitor, 2, args)
    monitor.graded_up_to = 6.1
    assert _finished(monitor, 2, args)
