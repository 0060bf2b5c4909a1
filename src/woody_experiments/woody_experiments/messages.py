"""The line's messages as the run report's records: live (`woody run` watches the line) or from a recorded bag.

`spawn_from_msg`, `verdict_from_msg` and `side_from_msg` flatten woody_msgs/FilletSpawn,
FilletVerdict and SideMetrics into :mod:`woody_experiments.run_report`'s `Spawn`, `Verdict` and `SideRecord`;
`rows_from_bag` and `settings_from_bag` read them back from a recording (`woody report BAG`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
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


def gate_margin(msg) -> tuple[tuple[int, int], float]:
    """A woody_msgs/GateCommand as (lane, fillet id) and its timing margin: how long before the diverter had to
    open the command was issued (s, sim time; the gate sends no command it could not act on in time)."""
    return (msg.lane, msg.fillet_id), stamp_to_seconds(msg.actuation_time) - stamp_to_seconds(msg.header.stamp)


@dataclass
class LineRecords:
    """What the line published about its fillets: ground truth, verdicts, side metrics and gate commands."""

    spawns: list[Spawn] = field(default_factory=list)
    verdicts: list[Verdict] = field(default_factory=list)
    sides: list[SideRecord] = field(default_factory=list)
    gated: dict[tuple[int, int], float] | None = field(default_factory=dict)
    """(lane, fillet id) of every GateCommand and its timing margin (:func:`gate_margin`); None when the gate's topic
    was not recorded."""

    def merged(self, other: LineRecords) -> LineRecords:
        """These records and ``other``'s, each message once: a verdict one record lost, the other may hold."""
        def union(mine: list, theirs: list, key) -> list:
            seen = {key(item) for item in mine}
            return mine + [item for item in theirs if key(item) not in seen]

        gated = None if self.gated is None and other.gated is None else (other.gated or {}) | (self.gated or {})
        return LineRecords(union(self.spawns, other.spawns, lambda s: s.sim_id),
                           union(self.verdicts, other.verdicts, lambda v: (v.lane, v.fillet_id)),
                           union(self.sides, other.sides, lambda s: (s.lane, s.fillet_id)), gated)

    def rows(self, woody_k: float = 50.0) -> list[dict]:
        """The verdict table's rows (woody_experiments.run_report.join)."""
        return join(self.spawns, self.verdicts, woody_k, gate_commands=self.gated, sides=self.sides)


def records_from_bag(path: Path) -> tuple[LineRecords, str | None]:
    """The line's records in a bag (of a line in any namespace), and where a truncated bag ends (None for a complete
    one): the readable part of a cut recording still counts."""
    records, ended = LineRecords(), None
    suffixes = {"/" + topics.GROUND_TRUTH: (spawn_from_msg, records.spawns.append),
                "/" + topics.VERDICTS: (verdict_from_msg, records.verdicts.append),
                "/" + topics.SIDE_METRICS: (side_from_msg, records.sides.append),
                "/" + topics.GATE_COMMANDS: (gate_margin, lambda entry: records.gated.update([entry]))}
    wanted = [t for t in bag_topics(path) if t.endswith(tuple(suffixes))]
    try:
        for topic, type_name, data, _log_time in read_bag(path, topics=wanted):
            flatten, keep = next(sink for suffix, sink in suffixes.items() if topic.endswith(suffix))
            keep(flatten(decode(type_name, data)))
    except BagError as exc:
        if not records.spawns and not records.verdicts:
            raise
        ended = str(exc)
    if not any(t.endswith("/" + topics.GATE_COMMANDS) for t in wanted):
        records.gated = None
    return records, ended


def rows_from_bag(path: Path, woody_k: float = 50.0) -> tuple[list[dict], str | None]:
    """Ground truth, verdicts, side metrics and gate commands recorded in a bag, joined into verdict-table rows, and
    where a truncated bag ends (None for a complete one). A bag without the gate's topic leaves the rows'
    ``gate_command`` unknown."""
    records, ended = records_from_bag(path)
    if not records.spawns and not records.verdicts:
        raise ValueError(f"{path}: no /line/ground_truth or /grading/verdicts messages in this bag")
    return records.rows(woody_k), ended


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
