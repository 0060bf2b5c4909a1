"""`woody run --live`: a client of the Foxglove WebSocket protocol watches the running line (the foxglove_view node).

The client (woody_bag.foxglove_client) is written from the protocol, not from foxglove-sdk, so the test checks
what a Foxglove app would receive.
"""

from __future__ import annotations

import csv
import subprocess
import time

import pytest

from woody_bag.foxglove_client import Watcher, served_port
from woody_bag.schemas import decode
from woody_bag.summary import bag_summary
from woody_common.calibration import resolved_calibration
from woody_tools.processes import entry_point, wait_for

pytestmark = pytest.mark.ros
"""Starts `woody run`."""

WATCHED = {"/top_camera/color/image_raw": "sensor_msgs/msg/Image",
           "/grading/annotations": "foxglove_msgs/msg/ImageAnnotations",
           "/grading/verdicts": "woody_msgs/msg/FilletVerdict", "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray"}


THRESHOLD = "/grader.threshold"


def read_only_parameters(client: Watcher, run: subprocess.Popen) -> tuple[float, float]:
    """The grader's threshold as a client reads it, and as it reads it after setting it to 1.0 (minus the
    first reading: 0.0 when neither moved); polls while the line runs."""
    read = changed = None
    while run.poll() is None and changed is None:
        if read is None:
            client.send({"op": "getParameters", "parameterNames": [], "id": "get"})
        else:
            client.send({"op": "setParameters", "id": "set", "parameters": [{"name": THRESHOLD, "value": 1.0}]})
        time.sleep(0.25)
        read = client.parameter_values.get("get", {}).get(THRESHOLD)
        changed = client.parameter_values.get("set", {}).get(THRESHOLD)
    assert read is not None and changed is not None, "no parameters while the line ran"
    return read - resolved_calibration().phi_threshold, changed - read


def test_a_foxglove_client_watches_the_live_line(tmp_path):
    out = tmp_path / "run"
    run = subprocess.Popen([entry_point("woody"), "run", "--fillets", "3", "--k", "0", "100", "--seed", "3",
                            "--live", "0", "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True)
    log = out / "logs" / "foxglove_view.log"
    try:
        assert wait_for(lambda: served_port(log) is not None, timeout=120), log.exists() and log.read_text()
        client = Watcher(f"ws://127.0.0.1:{served_port(log)}", set(WATCHED))
        parameters = read_only_parameters(client, run)
        stdout, stderr = run.communicate(timeout=600)
    finally:
        run.kill()
    assert run.returncode == 0, stderr[-3000:]
    client.join(timeout=30)
    assert client.error is None, client.error
    received, advertised = client.received, client.advertised
    assert "live view: Foxglove" in stderr
    assert {topic: advertised.get(topic) for topic in WATCHED} == WATCHED  # every topic with its ROS 2 schema
    verdicts = [decode(WATCHED["/grading/verdicts"], data) for data in received["/grading/verdicts"]]
    rows = list(csv.DictReader((out / "verdicts.csv").open()))
    assert sorted(v.fillet_id for v in verdicts) == sorted(int(r["fillet_id"]) for r in rows)  # every verdict
    assert received["/top_camera/color/image_raw"], "no colour frame"
    labelled = [decode(WATCHED["/grading/annotations"], data) for data in received["/grading/annotations"]]
    assert any(msg.texts and len(msg.texts) == len(msg.points) for msg in labelled)
    assert parameters == (0.0, 0.0)  # the grader's parameter as it is, after a client tried to set it
    health = [decode(WATCHED["/diagnostics"], data) for data in received["/diagnostics"]]
    assert {status.name.rsplit("/", 1)[-1] for msg in health for status in msg.status} >= {
        "line_sim", "segmenter", "grader", "reject_gate", "recorder"}
    # the same run's bag holds the annotations, the fixed frames and the health of every node
    topics = bag_summary(out / "line.mcap")["topics"]
    assert topics["/grading/annotations"]["count"] > 10 and topics["/tf_static"]["count"] == 1
    assert topics["/diagnostics"]["count"] >= 5
