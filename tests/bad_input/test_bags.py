"""The line's record under faults: a recorder at a full disk, a loaded machine, a starved recorder, replays into
live nodes. Nothing is lost silently: what cannot be kept is named in one line, what the recorder lost is counted
per topic where the user looks (terminal, report.md, the bag), and replaying never doubles a live node's output.

A full disk is stood in for by RLIMIT_FSIZE on the running recorder (EFBIG, handled like ENOSPC): mounting a
small filesystem needs privileges CI does not have.
"""

from __future__ import annotations

import csv
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import REPO, spin_until
from rclpy.qos import QoSProfile, ReliabilityPolicy

from bad_input.conftest import assert_one_clear_line
from woody_bag.summary import LOSSES_RECORD, bag_summary, losses_text, recorded_losses, recording_text
from woody_tools.line_run import LOST_NOTE
from woody_tools.processes import NodeProcess, entry_point, wait_for

pytestmark = pytest.mark.ros
"""Every test starts `woody run` or node entry points."""

SAMPLE = REPO / "bags" / "sample" / "line.mcap"
SAMPLE_FILLETS = 3


def start_run(tmp_path: Path, *args: str, env: dict[str, str] | None = None) -> subprocess.Popen:
    """`woody run ... --out tmp_path/run` in a process group of its own, its output in run.out / run.err."""
    env = {k: v for k, v in (env or os.environ).items() if env is not None or k != "ROS_DOMAIN_ID"}
    return subprocess.Popen([entry_point("woody"), "run", *args, "--out", str(tmp_path / "run")],
                            stdout=open(tmp_path / "run.out", "w"), stderr=open(tmp_path / "run.err", "w"),
                            stdin=subprocess.DEVNULL, env=dict(env, PYTHONUNBUFFERED="1"), cwd=tmp_path,
                            start_new_session=True)


def finish(run: subprocess.Popen, tmp_path: Path, timeout: float) -> tuple[int, str, str]:
    try:
        code = run.wait(timeout)
    except subprocess.TimeoutExpired:
        os.killpg(run.pid, signal.SIGKILL)
        code = run.wait()
    return code, (tmp_path / "run.out").read_text(), (tmp_path / "run.err").read_text()


def recorder_pid(out: Path, timeout: float = 60.0) -> int:
    """The pid of the recorder `woody run` started for ``out`` (its parameters file lies in out/logs)."""
    found: list[int] = []

    def look() -> bool:
        for entry in Path("/proc").iterdir():
            try:
                cmdline = (entry / "cmdline").read_bytes().split(b"\0")
            except (OSError, ValueError):
                continue
            if any(arg.endswith(b"/recorder") for arg in cmdline[:2]) and str(out).encode() in b" ".join(cmdline):
                found.append(int(entry.name))
                return True
        return False

    assert wait_for(look, timeout, interval=0.02), "the recorder did not start"
    return found[0]


def woody_lines(stderr: str) -> list[str]:
    """woody run's own lines on stderr (the progress lines every 10 s left out)."""
    return [line for line in stderr.splitlines() if line.startswith("woody run: ")]


def test_a_full_disk_is_one_line_and_keeps_the_graded_rows_and_the_bag(tmp_path):
    limit = 8_000_000  # about two thirds of a 12-fillet bag: the line stops half graded
    run = start_run(tmp_path, "--fillets", "12")
    resource.prlimit(recorder_pid(tmp_path / "run"), resource.RLIMIT_FSIZE, (limit, limit))
    code, out, err = finish(run, tmp_path, timeout=400)
    bag = tmp_path / "run" / "line.mcap"
    assert "Traceback" not in out + err, out + err
    assert code == 1, out + err
    lines = woody_lines(err)
    assert len(lines) == 1, err
    assert lines[0].startswith(f"woody run: recorder: stopped recording: {bag}: File too large (EFBIG)"), lines
    assert f"`woody bag recover {bag} OUT.mcap`" in lines[0], lines
    with open(tmp_path / "run" / "verdicts.csv") as handle:
        rows = list(csv.DictReader(handle))
    graded = [r for r in rows if r["verdict"] in ("normal", "woody", "unscored")]
    assert graded and all(r["verdict"] == r["truth"] for r in graded if r["verdict"] != "unscored"), rows

    assert bag.stat().st_size < limit and not bag_summary(bag)["complete"]
    fixed = tmp_path / "fixed.mcap"
    result = subprocess.run([entry_point("woody"), "bag", "recover", str(bag), str(fixed)], capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    from mcap.reader import make_reader
    from rosbags.highlevel import AnyReader

    with open(fixed, "rb") as handle:
        assert make_reader(handle).get_summary().statistics.message_count == bag_summary(fixed)["message_count"]
    with AnyReader([fixed]) as reader:
        verdicts = [c for c in reader.connections if c.topic == "/grading/verdicts"]
        assert len(list(reader.messages(connections=verdicts))) >= 1


def busy_processes(count: int = 2) -> list[subprocess.Popen]:
    """CPU hogs, each in a scheduling group of its own (setsid), like programs started from other terminals."""
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"], start_new_session=True)
            for _ in range(count)]


@pytest.mark.slow
def test_the_design_load_beside_two_busy_processes_loses_nothing(tmp_path):
    """3 lanes at 100 FPM (woody run's defaults), 36 fillets, two busy processes on the 2 cores."""
    hogs = busy_processes()
    try:
        code, out, err = finish(start_run(tmp_path, "--fillets", "36"), tmp_path, timeout=900)
    finally:
        for hog in hogs:
            hog.kill()
    assert code == 0, out + err
    bag = tmp_path / "run" / "line.mcap"
    summary = bag_summary(bag)
    assert summary["metadata"][LOSSES_RECORD]["total"] == "0", (tmp_path / "run" / "logs" / "recorder.log").read_text()
    recording = recording_text(summary)  # every node's health shares /diagnostics: its losses are not counted
    assert recording.startswith(f"{summary['message_count']} messages, no message lost"), recording
    assert f"bag: {bag} ({recording})" in out, out
    assert f"| recording | {recording} |" in (tmp_path / "run" / "report.md").read_text()


def test_a_line_faster_than_its_recorder_waits_for_it_and_loses_nothing(tmp_path):
    """woody run's line runs as fast as its consumers take it: a recorder stopped for 0.5 s (a disk that stalls;
    more than three times the line's lead) holds the line (line_sim waits on recorder/recorded_clock) instead of
    losing what it publishes meanwhile. Shared memory keeps what is queued for a reader stalled for less than its
    healthy_check_timeout_ms (1 s, config/fastdds.xml); a longer stall loses messages, counted per topic (below)."""
    run = start_run(tmp_path, "--fillets", "9")
    recorder = recorder_pid(tmp_path / "run")
    log = tmp_path / "run" / "logs" / "recorder.log"
    assert wait_for(lambda: log.exists() and "recording /top_camera/depth/image_raw" in log.read_text(), 60.0)
    time.sleep(1.0)
    os.kill(recorder, signal.SIGSTOP)
    time.sleep(0.5)
    os.kill(recorder, signal.SIGCONT)
    code, out, err = finish(run, tmp_path, timeout=300)
    assert code == 0, out + err
    bag = tmp_path / "run" / "line.mcap"
    assert recorded_losses(bag_summary(bag)["metadata"]) == {} and "no message lost" in out, out
    assert sum(1 for row in csv.DictReader(open(tmp_path / "run" / "verdicts.csv")) if row["verdict"]) == 9


def test_messages_lost_by_a_starved_recorder_are_counted_per_topic_where_the_user_looks(
        ros_domain, spawn_helper, tmp_path):
    """Beyond the design load: the recorder gets no CPU (SIGSTOP) while a publisher beside the line bursts 12,000
    images at it, more than the 8192 messages shared memory queues for it (config/fastdds.xml); four images a second
    before and after the burst bound it in sequence numbers, so what it lost is a gap. Its losses per topic are on
    the terminal, in report.md and in the bag's metadata."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain))
    run = start_run(tmp_path, "--fillets", "6", "--share-domain", env=env)
    out_dir = tmp_path / "run"
    pid = recorder_pid(out_dir)
    blaster = spawn_helper("image_blaster", "--count", "12000", "--on-signal", "--idle-hz", "4", "--width", "32",
                           "--height", "32")
    log, blaster_log = out_dir / "logs" / "recorder.log", tmp_path / "image_blaster.log"
    assert wait_for(lambda: "recording /blast/image_raw" in log.read_text(), 60), log.read_text()
    assert wait_for(lambda: "matched" in blaster_log.read_text(), 60), blaster_log.read_text()
    time.sleep(1.5)  # idle images reach the recorder before it stops
    os.kill(pid, signal.SIGSTOP)
    try:
        blaster.send_signal(signal.SIGUSR1)
        assert wait_for(lambda: "published" in blaster_log.read_text(), 8.0), blaster_log.read_text()
    finally:
        os.kill(pid, signal.SIGCONT)
    code, out, err = finish(run, tmp_path, timeout=400)
    assert code == 0 and "Traceback" not in out + err, out + err

    losses = recorded_losses(bag_summary(out_dir / "line.mcap")["metadata"])
    assert losses.get("/blast/image_raw", 0) >= 100, (losses, log.read_text())
    closing = log.read_text().splitlines()[-1]  # the recorder's own count: written/published per topic
    for topic, lost in losses.items():
        assert f"{topic} " in closing and f"(lost {lost})" in closing.split(f"{topic} ", 1)[1].split(",")[0]
    said = losses_text(losses)
    assert said.startswith(f"{sum(losses.values())} messages lost (") and "/blast/image_raw" in said
    assert woody_lines(err) == [f"woody run: recorder: {said}: {LOST_NOTE}"], err
    recording = recording_text(bag_summary(out_dir / "line.mcap"))  # <n> messages, <said>; what is not counted
    assert f"messages, {said}" in recording and f"{recording})" in out, out  # bag: <path> (<recording>)
    report = (out_dir / "report.md").read_text()
    assert f"- recorder: {said}" in report and f"{recording} |" in report
    info = subprocess.run([entry_point("woody"), "bag", "info", str(out_dir)], capture_output=True, text=True,
                          timeout=60)
    assert said in info.stdout, info.stdout


def start_vision(domain: int, tmp_path: Path) -> list[NodeProcess]:
    """A live segmenter, grader and reject gate as `woody run` configures them for the sample's 3 lanes."""
    vision = {"use_sim_time": True, "lanes": 3}
    return [NodeProcess("segmenter", vision, domain_id=domain, log_dir=tmp_path),
            NodeProcess("grader", vision, domain_id=domain, log_dir=tmp_path),
            NodeProcess("reject_gate", {"use_sim_time": True, "lanes": 3, "line_speed_fpm": 100.0},
                        domain_id=domain, log_dir=tmp_path)]


def replay_and_collect(ros_node, domain: int, log_dir: Path, received: list, *args: str) -> tuple[list, str]:
    """Replay the whole sample (every topic, its clock) into the live nodes; the verdicts it brought and its log."""
    before = len(received)
    replay = NodeProcess("woody", None, domain_id=domain, log_dir=log_dir,
                         extra_args=["replay", str(SAMPLE), "--progress", "0", *args])
    try:
        spin_until(ros_node, lambda: not replay.alive(), timeout=120.0)
        spin_until(ros_node, lambda: False, timeout=4.0)  # the last fillet's verdict is due after the bag ends
    finally:
        code = replay.stop()
    log = replay.log_path.read_text()
    assert code == 0, log
    return received[before:], log


def test_replaying_twice_and_faster_into_live_nodes_gives_one_verdict_per_fillet(ros_node, ros_domain, tmp_path):
    from woody_msgs.msg import FilletVerdict

    received: list = []
    ros_node.create_subscription(FilletVerdict, "/grading/verdicts", received.append,
                                 QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
    nodes = start_vision(ros_domain, tmp_path)
    try:
        assert spin_until(ros_node, lambda: ros_node.count_publishers("/grading/verdicts") >= 1
                          and ros_node.count_publishers("/reject_gate/commands") >= 1
                          and ros_node.count_subscribers("/vision/tracks") >= 1, timeout=90.0)
        passes = [replay_and_collect(ros_node, ros_domain, tmp_path / name, received, *args)
                  for name, args in (("first", ()), ("second", ()), ("rate4", ("--rate", "4")))]
    finally:
        for node in nodes:
            node.stop()
    logs = "\n".join(log for _, log in passes) + "\n".join(n.log_tail() for n in nodes)
    for verdicts, log in passes:  # skipped at the start, or as soon as playback saw them (before any verdict)
        assert "replay: not replaying topics live nodes publish" in log or "not replayed from t=0.000s" in log, log
        for topic in ("/vision/tracks", "/grading/verdicts", "/grading/annotations", "/reject_gate/commands"):
            # by the node's name (? when its publisher is known before its name), or as recorded with an older type
            assert f"{topic} (by " in log or f"replay: skipping {topic}: recorded with an older" in log, log
        assert len(verdicts) == SAMPLE_FILLETS, logs
    first, second = ([(v.lane, v.classification, v.header.stamp.sec, v.header.stamp.nanosec) for v in verdicts]
                     for verdicts, _ in passes[:2])
    assert sorted(first) == sorted(second), logs


TRACKS = "/vision/tracks"
REPLAY = ("--topics", TRACKS, "--no-clock", "--wait-for-subscribers", "0", "--discovery", "0", "--quiet")


def bag_recorded_with(path: Path, edit, monkeypatch) -> Path:
    """Five /vision/tracks messages in a bag whose recorded FilletTrackArray definition is ``edit`` of this
    workspace's (as a bag written before the .msg file changed holds it)."""
    from fixtures.known_messages import known
    from rclpy.serialization import serialize_message

    from woody_bag import writer

    current = writer.message_definition
    with monkeypatch.context() as patched:
        patched.setattr(writer, "message_definition", lambda type_name: edit(current(type_name)))
        with writer.BagWriter(path) as bag:
            bag.add_topic(TRACKS, "woody_msgs/msg/FilletTrackArray")
            for i in range(5):
                bag.write(TRACKS, serialize_message(known(TRACKS, i)), 1_700_000_000 * 10**9 + i * 10**8)
    return path


def test_a_definition_changed_in_its_comments_replays_and_one_changed_in_a_field_is_one_line(
        entry, tmp_path, monkeypatch):
    """Comments and spacing are not the type: such a topic plays as it is. A field of another type cannot be
    decoded by this workspace's woody_msgs: refused with one line saying why."""
    def commented(text: str) -> str:
        return "# written before a comment was added\n" + text.replace(
            "uint32 image_width            # px", "uint32   image_width # pixels across the frame")

    def retyped(text: str) -> str:
        return text.replace("uint32 image_width", "uint16 image_width")

    from woody_bag.schemas import message_definition

    assert "uint32 image_width            # px" in message_definition("woody_msgs/msg/FilletTrackArray")
    played = entry("woody", "replay", str(bag_recorded_with(tmp_path / "commented.mcap", commented, monkeypatch)),
                   *REPLAY, timeout=60)
    assert played.code == 0 and played.lines == [], played.lines
    old = bag_recorded_with(tmp_path / "retyped.mcap", retyped, monkeypatch)
    refused = entry("woody", "replay", str(old), *REPLAY, timeout=60)
    assert_one_clear_line(refused, "replay", f"{old}: nothing playable in the selected topics (skipping {TRACKS}: "
                                             "recorded with an older woody_msgs/msg/FilletTrackArray definition")
