"""The line's messages as the run report's records: live (`woody run` watches the line) or from a recorded bag.

`spawn_from_msg`, `verdict_from_msg` and `side_from_msg` flatten woody_msgs/FilletSpawn,
FilletVerdict and SideMetrics into :mod:`woody_experiments.run_report`'s `Spawn`, `Verdict` and `SideRecord`;
`rows_from_bag` and `settings_from_bag` read them back from a recording (`woody report BAG`).
"""

from __future__ import annotations

import json
from pathlib import Path

from woody_bag.errors import BagError
from woody_bag.reader import read_bag
from woody_bag.schemas import decode
from woody_bag.summary import bag_summary, bag_topics, recording_text
from woody_common import topics
from woody_common.stamps import stamp_to_seconds
from woody_experiments.run_report import RECORDING, SideRecord, Spawn, Verdict, join


def spawn_from_msg(msg) -> Spawn:
    """Flatten a woody_msgs/FilletSpawn (the line's ground truth) into the report's Spawn."""
    return Spawn(sim_id=msg.fillet_id, lane=msg.lane, mesh=msg.mesh, k=msg.stiffness, mass=msg.mass,
                 line_speed=msg.line_speed, stamp=stamp_to_seconds(msg.header.stamp), spawn_x=msg.position.x)


def verdict_from_msg(msg) -> Verdict:
    """Flatten a woody_msgs/FilletVerdict into the report's Verdict."""
    classes = {msg.CLASS_NORMAL: "normal", msg.CLASS_WOODY: "woody", msg.CLASS_UNSCORED: "unscored"}
    return Verdict(fillet_id=msg.fillet_id, lane=msg.lane, stamp=stamp_to_seconds(msg.header.stamp),
                   classification=classes.get(msg.classification, "unscored"), grade=msg.grade, phi=msg.phi,
                   hu_term=msg.hu_term, solidity_term=msg.solidity_term, reason=msg.unscored_reason,
                   threshold=msg.threshold, score=msg.score, line_phi=msg.line_phi, line_fraction=msg.line_fraction,
                   speed=msg.speed, leading_end=msg.leading_end, rejected_frames=int(msg.rejected_frames))


def side_from_msg(msg) -> SideRecord:
    """Flatten a woody_msgs/SideMetrics (the watched lane's side view) into the report's SideRecord."""
    return SideRecord(fillet_id=msg.fillet_id, lane=msg.lane, nmdm=msg.nmdm, mdm=msg.mdm, be=msg.be,
                      reason=msg.reason)


def rows_from_bag(path: Path, woody_k: float = 50.0) -> tuple[list[dict], str | None]:
    """Ground truth, verdicts, side metrics and gate commands recorded in a bag (of a line in any namespace), joined
    into verdict-table rows, and where a truncated bag ends (None for a complete one): the readable part of a cut
    recording still counts. A bag without the gate's topic leaves the rows' ``gate_command`` unknown."""
    spawns, verdicts, sides, gated, ended = [], [], [], set(), None
    suffixes = {"/" + topics.GROUND_TRUTH: "spawn", "/" + topics.VERDICTS: "verdict",
                "/" + topics.SIDE_METRICS: "side", "/" + topics.GATE_COMMANDS: "gate"}
    try:
        wanted = [t for t in bag_topics(path) if t.endswith(tuple(suffixes))]
        for topic, type_name, data, _log_time in read_bag(path, topics=wanted):
            msg = decode(type_name, data)
            kind = next(kind for suffix, kind in suffixes.items() if topic.endswith(suffix))
            if kind == "spawn":
                spawns.append(spawn_from_msg(msg))
            elif kind == "verdict":
                verdicts.append(verdict_from_msg(msg))
            elif kind == "side":
                sides.append(side_from_msg(msg))
            else:
                gated.add((msg.lane, msg.fillet_id))
    except BagError as exc:
        if not spawns and not verdicts:
            raise
        ended = str(exc)
    if not spawns and not verdicts:
        raise ValueError(f"{path}: no /line/ground_truth or /grading/verdicts messages in this bag")
    has_gate = any(t.endswith("/" + topics.GATE_COMMANDS) for t in wanted)
    return join(spawns, verdicts, woody_k, gate_commands=gated if has_gate else None, sides=sides), ended


def settings_from_bag(path: Path, rows: list[dict]) -> dict | None:
    """The settings table of the run that recorded the bag (the recorder's ``woody.run`` record)."""
    summary = bag_summary(path)
    record = summary["metadata"].get("woody", {}).get("run_settings")
    if not record:
        return None
    settings = json.loads(record)
    settings[RECORDING] = recording_text(summary)
    settings["fillets spawned"] = sum(1 for r in rows if r.get("truth"))
    settings["verdicts"] = sum(1 for r in rows if r["verdict"] != "missing")
    return settings
