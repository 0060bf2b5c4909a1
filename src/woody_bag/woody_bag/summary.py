"""What a bag holds (topics, types, counts, QoS, duration, metadata), cheaply for complete files."""

from __future__ import annotations

import os
from typing import Any

from mcap.reader import SeekingReader
from mcap.records import Channel, Message, Metadata, Schema

from woody_bag.errors import Truncated
from woody_bag.records import open_bag, read_summary, span_text, stream_records


def bag_topics(path: str | os.PathLike) -> dict[str, str]:
    """{topic: type name (pkg/msg/Type)} of a bag; a truncated bag is scanned as far as it reads."""
    return {topic: info["type"] for topic, info in bag_summary(path)["topics"].items()}


def bag_summary(path: str | os.PathLike) -> dict[str, Any]:
    """What a bag holds, cheaply for complete files.

    ``{"path", "complete", "topics": {topic: {"type", "definition", "count", "qos"}}, "message_count",
    "start_ns", "end_ns", "duration_s", "metadata": {name: {...}}, "error"}`` where ``error``
    is the truncation message of an incomplete file (else ``None``). Counts of an
    incomplete file are those of its readable part.
    """
    path, handle = open_bag(path)
    try:
        summary = read_summary(path, handle)
        result: dict[str, Any] = {"path": str(path), "complete": summary is not None, "topics": {},
                                  "metadata": {}, "error": None}
        if summary is not None:
            _summarise_complete(result, summary, handle)
        else:
            _summarise_by_scanning(result, path, handle)
        result["duration_s"] = max(0, result["end_ns"] - result["start_ns"]) / 1e9
        return result
    finally:
        handle.close()


def _summarise_complete(result: dict[str, Any], summary, handle) -> None:
    """Fill ``result`` from a complete file's summary section and metadata index."""
    stats = summary.statistics
    counts = dict(stats.channel_message_counts) if stats else {}
    for cid, channel in summary.channels.items():
        schema = summary.schemas.get(channel.schema_id)
        result["topics"][channel.topic] = {
            "type": schema.name if schema else "", "definition": _schema_text(schema),
            "count": counts.get(cid, 0),
            "qos": channel.metadata.get("offered_qos_profiles", "")}
    result["message_count"] = stats.message_count if stats else sum(counts.values())
    result["start_ns"] = stats.message_start_time if stats else 0
    result["end_ns"] = stats.message_end_time if stats else 0
    handle.seek(0)
    for record in SeekingReader(handle).iter_metadata():
        result["metadata"][record.name] = dict(record.metadata)


def _summarise_by_scanning(result: dict[str, Any], path, handle) -> None:
    """Fill ``result`` by reading an incomplete file record by record up to where it ends."""
    handle.seek(0)
    schemas: dict[int, Schema] = {}
    channels: dict[int, str] = {}
    count, start, end = 0, None, None
    try:
        for record in stream_records(handle):
            if isinstance(record, Message):
                topic = channels.get(record.channel_id)
                if topic is None:
                    continue
                result["topics"][topic]["count"] += 1
                count += 1
                start = record.log_time if start is None else min(start, record.log_time)
                end = record.log_time if end is None else max(end, record.log_time)
            elif isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record.topic
                schema = schemas.get(record.schema_id)
                result["topics"].setdefault(record.topic, {
                    "type": schema.name if schema else "", "definition": _schema_text(schema), "count": 0,
                    "qos": record.metadata.get("offered_qos_profiles", "")})
            elif isinstance(record, Metadata):
                result["metadata"][record.name] = dict(record.metadata)
    except Truncated:
        result["error"] = f"{path}: truncated after {count} messages at {span_text(start, end)}"
    result["message_count"] = count
    result["start_ns"] = start or 0
    result["end_ns"] = end or 0


def _schema_text(schema: Schema | None) -> str:
    return schema.data.decode(errors="replace") if schema is not None else ""


def bag_metadata(path: str | os.PathLike) -> dict[str, dict[str, str]]:
    """The bag's metadata records, e.g. ``{"woody": {...run info...}}``."""
    return bag_summary(path)["metadata"]


LOSSES_RECORD = "woody.losses"
"""The recorder's metadata record of the messages published but not recorded: ``total``, ``unmeasured`` (topics whose
publishers gave no usable sequence numbers) and the count of every topic that lost some."""


def losses_record(drops: dict[str, tuple[int, int | None]]) -> dict[str, str]:
    """The `LOSSES_RECORD` of the recorder's per-topic (written, published) counts."""
    lost = {topic: published - written for topic, (written, published) in drops.items()
            if published is not None and published > written}
    unmeasured = sorted(topic for topic, (_written, published) in drops.items() if published is None)
    return {"total": str(sum(lost.values())), "unmeasured": ",".join(unmeasured),
            **{topic: str(n) for topic, n in sorted(lost.items())}}


def recorded_losses(metadata: dict[str, dict[str, str]]) -> dict[str, int] | None:
    """{topic: messages lost} of a bag's metadata (empty: none lost); None when the recorder did not
    finish the bag (no `LOSSES_RECORD`)."""
    record = metadata.get(LOSSES_RECORD)
    if record is None:
        return None
    return {topic: int(n) for topic, n in record.items() if topic.startswith("/")}


def _unmeasured(summary: dict[str, Any]) -> list[str]:
    return [t for t in summary["metadata"].get(LOSSES_RECORD, {}).get("unmeasured", "").split(",") if t]


def unrecorded_topics(summary: dict[str, Any]) -> list[str]:
    """The topics of a `bag_summary` the recorder subscribed to (a publisher was there) and received no message on: a
    recorder cut off from its publishers counts no loss there, so this is said instead."""
    return [t for t in _unmeasured(summary) if not summary["topics"].get(t, {}).get("count")]


def unmeasured_text(summary: dict[str, Any]) -> str:
    """"", "; nothing recorded on /a" and/or "; losses not measured on /b, /c (...)": the topics of a `bag_summary`
    whose losses the recorder could not count."""
    empty = unrecorded_topics(summary)
    shared = [t for t in _unmeasured(summary) if t not in empty]
    return ((f"; nothing recorded on {', '.join(empty)}" if empty else "")
            + (f"; losses not measured on {', '.join(shared)} (their publishers give no usable sequence numbers)"
               if shared else ""))


def recording_text(summary: dict[str, Any]) -> str:
    """A `bag_summary` in one phrase for the terminal and report.md: "5133 messages, no message lost"."""
    losses = losses_text(recorded_losses(summary["metadata"]))
    return f"{summary['message_count']} messages, {losses}{unmeasured_text(summary)}"


def losses_text(losses: dict[str, int] | None) -> str:
    """``"no message lost"``, ``"19 messages lost (/clock 13, ...)"`` or, for a bag
    without `LOSSES_RECORD` (its recorder did not finish it, or another recorder wrote it), that they are not
    recorded."""
    if losses is None:
        return "losses not recorded"
    if not losses:
        return "no message lost"
    return (f"{sum(losses.values())} messages lost ("
            + ", ".join(f"{t} {n}" for t, n in sorted(losses.items(), key=lambda item: -item[1])) + ")")
