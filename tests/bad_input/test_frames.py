"""Frames lost, late or seen twice by the vision nodes: every published value is measured on complete data, or it
is absent with the reason.

The line is `woody run --fillets 12` (seed 7: four fillets in the side camera's lane) with its grader disturbed:
paused (SIGSTOP) for a second every 1.5 s, started from an empty numba cache, or sharing the two cores with two
busy loops. Each verdict must match the same run undisturbed (warm cache, idle machine) within the run-to-run
spread, or have the disturbed value absent (NaN) with the reason in ``unscored_reason`` (or, for the side view's
NMDM, MDM and BE, in its /grading/side_metrics ``reason``). The same camera topics replayed twice into the same
live segmenter, grader and reject gate must give the same verdicts twice.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest
from conftest import REPO, spin_until
from rclpy.qos import QoSProfile, ReliabilityPolicy

from woody_tools.processes import NodeProcess, entry_point

pytestmark = pytest.mark.ros
"""Starts `woody run`, node entry points and `woody replay` as processes."""

FILLETS = 12
RUN_TIMEOUT_S = 300
PAUSE_S = 1.0
PAUSE_EVERY_S = 1.5
ATTEMPTS = 2
"""Runs tried for a run that measured every watched fillet: on a machine loaded far beyond its cores a grader can
fall behind the side camera in any run and publish an NMDM absent (with its reason, never a partial value)."""
HOG_RUNS = 2
"""Runs beside two CPU hogs in the suite (each ~40 s on a loaded 2-core machine)."""
WATCHED_LANE = 1
SPREAD = {"score": 0.02, "line_phi": 0.02, "phi": 0.02, "hu_term": 0.02, "solidity_term": 0.05, "nmdm": 0.01,
          "mdm": 0.01, "be": 0.25}
"""Largest relative difference from the warm run taken as run-to-run spread. Whole runs agree to 4 digits; the
margin is for the one lost frame a measurement tolerates (Φ_t or MDM of that frame missing). A partial passage
was 1.2 % off (NMDM 0.812 for 0.802) to 190 % (2.27 for 0.79)."""
VALUES = tuple(SPREAD)
SAMPLE = REPO / "bags" / "sample" / "line.mcap"
CAMERA_TOPICS = ["/top_camera/depth/image_raw", "/top_camera/depth/camera_info", "/side_camera/image_raw",
                 "/line/ground_truth"]


def run_line(out: Path, env: dict | None = None, during=None) -> list:
    """`woody run --fillets 12` into ``out``; ``during(run)`` is called while it runs. Its verdicts, from its bag."""
    run = subprocess.Popen([entry_point("woody"), "run", "--fillets", str(FILLETS), "--out", str(out)],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    try:
        if during is not None:
            during(run)
        output, _ = run.communicate(timeout=RUN_TIMEOUT_S)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
    assert run.returncode == 0, output
    return recorded_verdicts(out / "line.mcap")


@dataclass(frozen=True)
class Graded:
    """A verdict with its side metrics (paired by fillet id): NMDM, MDM and BE are NaN when not measured, and the
    side's reason joins the verdict's ``unscored_reason``; everything else is the verdict's."""

    verdict: object
    side: object | None = None

    def __getattr__(self, name: str):
        if name in ("nmdm", "mdm", "be"):
            return getattr(self.side, name) if self.side is not None else math.nan
        if name == "unscored_reason":
            reasons = (self.verdict.unscored_reason, self.side.reason if self.side is not None else "")
            return "; ".join(r for r in reasons if r)
        return getattr(self.verdict, name)


def graded(verdicts: list, sides: list) -> list[Graded]:
    by_fillet = {m.fillet_id: m for m in sides}
    return [Graded(v, by_fillet.get(v.fillet_id)) for v in verdicts]


def recorded_verdicts(bag: Path) -> list[Graded]:
    from woody_bag.reader import read_bag
    from woody_bag.schemas import decode

    messages = {"/grading/verdicts": [], "/grading/side_metrics": []}
    for topic, type_name, data, _ in read_bag(bag, topics=list(messages)):
        messages[topic].append(decode(type_name, data))
    return graded(*messages.values())


def measured_every_watched_fillet(out: Path, env_of_a_run=lambda: None, check=lambda verdicts: None) -> list:
    """The verdicts of the first of ATTEMPTS runs into ``out``-1, -2, ... (each in the environment
    ``env_of_a_run()`` gives it, each passing ``check``) whose four watched-lane verdicts all carry an NMDM."""
    for attempt in range(1, ATTEMPTS + 1):
        verdicts = run_line(out.with_name(f"{out.name}-{attempt}"), env=env_of_a_run())
        check(verdicts)
        assert len(verdicts) == FILLETS and len(watched_nmdms(verdicts)) == 4
        missing = [v.unscored_reason for v in verdicts if v.lane == WATCHED_LANE and math.isnan(v.nmdm)]
        assert all(missing), "an absent NMDM says why"
        if not missing:
            return verdicts
        print(f"{out.name} run {attempt}: watched-lane NMDM absent: {missing}")
    raise AssertionError(f"{ATTEMPTS} runs, none measured every watched fillet: {missing}")


@pytest.fixture(scope="module")
def warm(tmp_path_factory) -> list:
    """An undisturbed run's verdicts (the numba cache as the test environment has it: warm after the first run)."""
    return measured_every_watched_fillet(tmp_path_factory.mktemp("warm") / "run")


def key(verdict) -> tuple[int, int, int]:
    return verdict.lane, verdict.header.stamp.sec, verdict.header.stamp.nanosec


def assert_nothing_wrong(got: list, warm: list, what: str) -> int:
    """Every warm verdict is there, each value within the spread or absent (NaN) with a reason; returns how many
    values were absent."""
    assert sorted(map(key, got)) == sorted(map(key, warm)), f"{what}: other verdicts than the warm run's"
    absent = 0
    for g, w in zip(sorted(got, key=key), sorted(warm, key=key)):
        name = f"{what}: fillet at {key(w)}"
        if g.classification != w.classification:
            assert g.classification == g.CLASS_UNSCORED and g.unscored_reason, (name, g.unscored_reason)
        for field in VALUES:
            value, reference = getattr(g, field), getattr(w, field)
            if math.isnan(value) and not math.isnan(reference):
                assert g.unscored_reason, f"{name}: {field} absent without a reason"
                absent += 1
            elif not math.isnan(reference):
                assert value == pytest.approx(reference, rel=SPREAD[field]), (name, field, g.unscored_reason)
    return absent


def watched_nmdms(verdicts: list) -> list[float]:
    return [v.nmdm for v in sorted(verdicts, key=key) if v.lane == WATCHED_LANE]


def test_the_warm_run_measures_every_watched_fillet(warm):
    """The reference itself: 12 verdicts, four in the watched lane, each with its side-view metrics."""
    nmdms = watched_nmdms(warm)
    assert all(0.2 < n < 1.5 for n in nmdms), nmdms


def grader_of(run: subprocess.Popen) -> int:
    """The pid of the run's grader, once it has started."""
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and run.poll() is None:
        found = subprocess.run(["pgrep", "-P", str(run.pid), "-f", "bin/grader --ros-args"], capture_output=True,
                               text=True).stdout.split()
        if found:
            return int(found[0])
        time.sleep(0.05)
    raise AssertionError("woody run started no grader")


def pause_grader(run: subprocess.Popen) -> None:
    """SIGSTOP the run's grader for PAUSE_S every PAUSE_EVERY_S until the run ends (SIGCONT always follows)."""
    grader = grader_of(run)
    try:
        while run.poll() is None:
            time.sleep(PAUSE_EVERY_S - PAUSE_S)
            os.kill(grader, signal.SIGSTOP)
            time.sleep(PAUSE_S)
            os.kill(grader, signal.SIGCONT)
    except ProcessLookupError:
        return  # the run ended and its grader with it
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(grader, signal.SIGCONT)


def test_a_grader_paused_every_1_5_s_publishes_no_wrong_side_value(warm, tmp_path):
    got = run_line(tmp_path / "paused", during=pause_grader)
    absent = assert_nothing_wrong(got, warm, "grader paused")
    nmdms = watched_nmdms(got)
    assert len(nmdms) == 4
    print(f"paused grader: {absent} values absent with their reason; watched-lane NMDM {nmdms}, warm "
          f"{watched_nmdms(warm)}")


def test_a_run_from_an_empty_numba_cache_gives_the_warm_verdicts(warm, tmp_path):
    """Each attempt starts from its own empty cache: the nodes compile before they subscribe, so the first
    passage is measured whole."""
    caches = []

    def cold_env() -> dict:
        caches.append(tmp_path / f"numba-cache-{len(caches) + 1}")
        caches[-1].mkdir()
        return dict(os.environ, NUMBA_CACHE_DIR=str(caches[-1]))

    got = measured_every_watched_fillet(tmp_path / "cold", cold_env,
                                        check=lambda verdicts: assert_nothing_wrong(verdicts, warm, "cold cache"))
    assert all(any(cache.rglob("*.nbi")) for cache in caches), "each run compiled into its empty cache"
    assert assert_nothing_wrong(got, warm, "cold cache") == 0
    assert watched_nmdms(got) == pytest.approx(watched_nmdms(warm), rel=SPREAD["nmdm"])


@pytest.mark.slow
def test_two_cpu_hogs_beside_the_line_change_no_published_value(warm, tmp_path):
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        for i in range(HOG_RUNS):
            absent = assert_nothing_wrong(run_line(tmp_path / f"hogs{i}"), warm, f"run {i} beside two CPU hogs")
            print(f"run {i} beside two CPU hogs: {absent} values absent with their reason")
    finally:
        for hog in hogs:
            hog.kill()
            hog.wait()


def test_the_same_camera_topics_replayed_twice_give_the_same_verdicts_twice(ros_node, ros_domain, tmp_path):
    from woody_msgs.msg import FilletVerdict, SideMetrics

    received: list = []
    sides: list = []
    ros_node.create_subscription(FilletVerdict, "/grading/verdicts", received.append,
                                 QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))
    ros_node.create_subscription(SideMetrics, "/grading/side_metrics", sides.append,
                                 QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))
    params = {"use_sim_time": True, "lanes": 3}
    nodes = [NodeProcess(name, params, domain_id=ros_domain, log_dir=tmp_path)
             for name in ("segmenter", "grader", "reject_gate")]
    try:
        assert spin_until(ros_node, lambda: ros_node.count_subscribers("/vision/tracks") >= 1
                          and ros_node.count_subscribers("/grading/verdicts") >= 2, timeout=60.0)
        passes = [replay_pass(ros_node, ros_domain, tmp_path / f"replay{i}", received, sides) for i in range(2)]
    finally:
        for node in nodes:
            node.stop()
    logs = {node.name: node.log_path.read_text() for node in nodes}
    first, second = passes
    assert len(first) == len(second) == 3, logs["grader"]
    assert [fields(v) for v in sorted(first, key=key)] == [fields(v) for v in sorted(second, key=key)]
    assert any(v.lane == WATCHED_LANE and math.isfinite(v.nmdm) for v in second), "the watched lane's NMDM"
    for name, log in logs.items():
        assert log.count("sim time went back") == 1, f"{name}: one line when the second pass starts\n{log}"


def replay_pass(ros_node, ros_domain: int, log_dir: Path, received: list, sides: list) -> list[Graded]:
    """Replay the sample's camera topics (and its /clock) once; the verdicts that came of it, with their side
    metrics."""
    start, sides_start = len(received), len(sides)
    replay = NodeProcess("woody", None, domain_id=ros_domain, log_dir=log_dir,
                         extra_args=["replay", str(SAMPLE), "--topics", *CAMERA_TOPICS])
    spin_until(ros_node, lambda: not replay.alive(), timeout=120.0)
    spin_until(ros_node, lambda: len(received) >= start + 3 and len(sides) > sides_start, timeout=10.0)
    assert replay.stop() == 0, replay.log_tail()
    return graded(received[start:], sides[sides_start:])


def fields(verdict) -> tuple:
    """What a verdict says, NaN made comparable (the track id counts on across passes and is left out)."""
    values = [getattr(verdict, f) for f in ("lane", "classification", "grade", "unscored_reason", *VALUES)]
    return (verdict.header.stamp.sec, verdict.header.stamp.nanosec,
            *("nan" if isinstance(v, float) and math.isnan(v) else v for v in values))
