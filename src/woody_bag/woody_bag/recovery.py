"""Rescuing a recording cut short: every complete chunk rewritten into a valid, indexed bag."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from mcap.records import Channel, Message, Metadata, Schema

from woody_bag.errors import BagError, Truncated
from woody_bag.records import open_bag, span_text, stream_records
from woody_bag.writer import ROSBAG2_RECORD, BagWriter


def recover_bag(source: str | os.PathLike, target: str | os.PathLike, *, overwrite: bool = False) -> dict[str, Any]:
    """Rewrite every complete chunk of ``source`` (e.g. a SIGKILLed recording) into a valid, indexed ``target``.

    Schemas, channels (with their QoS metadata), messages and metadata records are copied
    in file order; the ``woody.recover`` metadata record says what was recovered and where
    the source ended. Returns ``{"messages", "topics", "error"}`` (``error`` is the
    truncation line of the source, ``None`` when it was complete). `BagError` (one line)
    when the source is unreadable from the start or the target cannot be written.
    """
    path, handle = open_bag(source)
    if Path(target).resolve() == path.resolve():
        handle.close()
        raise BagError(f"{target}: the output must differ from the input")
    state: dict[str, Any] = {"writer": None, "metadata": {}, "schemas": {}, "channels": {}, "count": 0,
                             "first": None, "last": None}
    error = None
    try:
        handle.seek(0)
        try:
            for record in stream_records(handle):
                _copy_record(record, state, target, overwrite)
        except Truncated:
            error = f"{path}: truncated after {state['count']} messages at {span_text(state['first'], state['last'])}"
        writer = state["writer"] or _recovery_writer(target, state, overwrite)
        writer.add_metadata("woody.recover", {"source": str(path), "messages": str(state["count"]),
                                              "source_end": error or "complete"})
        writer.close()
    finally:
        handle.close()
    return {"messages": state["count"], "topics": dict(writer.counts), "error": error}


def _recovery_writer(target: str | os.PathLike, state: dict[str, Any], overwrite: bool) -> BagWriter:
    """The target's writer, created once the source's leading metadata records are known."""
    metadata = state["metadata"]
    writer = BagWriter(target, metadata=metadata.pop("woody", None), overwrite=overwrite)
    for name, data in metadata.items():
        writer.add_metadata(name, data)
    state["writer"] = writer
    return writer


def _copy_record(record: Any, state: dict[str, Any], target: str | os.PathLike, overwrite: bool) -> None:
    """Copy one data-section record of a bag being recovered into the target."""
    if isinstance(record, Metadata):
        if record.name == ROSBAG2_RECORD:
            return  # the copy's own, of what it holds, is written when it closes
        if state["writer"] is None:
            state["metadata"][record.name] = dict(record.metadata)
        else:
            state["writer"].add_metadata(record.name, dict(record.metadata))
        return
    writer = state["writer"] or _recovery_writer(target, state, overwrite)
    if isinstance(record, Schema):
        state["schemas"][record.id] = record
    elif isinstance(record, Channel):
        schema = state["schemas"].get(record.schema_id)
        if schema is not None:
            writer.add_topic(record.topic, schema.name, record.metadata.get("offered_qos_profiles", ""),
                             definition=schema.data, topic_type_hash=record.metadata.get("topic_type_hash"))
            state["channels"][record.id] = record.topic
    elif isinstance(record, Message) and record.channel_id in state["channels"]:
        writer.write(state["channels"][record.channel_id], record.data, record.log_time, record.publish_time,
                     record.sequence)
        state["first"] = record.log_time if state["first"] is None else state["first"]
        state["last"] = record.log_time
        state["count"] += 1
