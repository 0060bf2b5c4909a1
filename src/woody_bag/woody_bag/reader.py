"""Reading a bag: every message (or a topic selection) in log-time order, or as far as a cut-short file reads."""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from typing import NamedTuple

from mcap.reader import SeekingReader
from mcap.records import Channel, Message, Schema

from woody_bag.errors import BagError, Truncated
from woody_bag.records import open_bag, read_summary, span_text, stream_records


class BagMessage(NamedTuple):
    topic: str
    type_name: str
    data: bytes
    log_time: int


def read_bag(path: str | os.PathLike, topics: Iterable[str] | None = None) -> Iterator[BagMessage]:
    """Every message of the bag (or of ``topics``) as `BagMessage` (topic, type_name, data, log_time).

    A complete file is read through its summary in log-time order. A file without a
    summary (a killed recorder) is read as a stream in file order: everything readable
    is yielded, then `BagError` says ``"<path>: truncated after N messages at t=...s"``
    (N and t over every topic of the file, t from its first message). Missing file /
    not an MCAP: `BagError` at the first ``next()``.
    """
    path, handle = open_bag(path)
    wanted = None if topics is None else set(topics)
    count = 0
    first = last = None
    try:
        summary = read_summary(path, handle)
        if summary is not None:
            handle.seek(0)
            reader = SeekingReader(handle, validate_crcs=True)  # crc32 runs at ~4 GB/s here
            try:
                for schema, channel, message in reader.iter_messages(topics=wanted, log_time_order=True):
                    if first is None:
                        first = message.log_time
                    last = message.log_time
                    count += 1
                    yield BagMessage(channel.topic, schema.name if schema else "", message.data, message.log_time)
            except Exception as exc:  # noqa: BLE001 - zstd, struct, mcap errors alike: damaged data
                raise BagError(f"{path}: corrupt after {count} messages at {span_text(first, last)} "
                               f"({type(exc).__name__}: {exc})".replace("\n", " ")) from None
            return
        handle.seek(0)
        schemas: dict[int, str] = {}
        channels: dict[int, tuple[str, str]] = {}
        try:
            for record in stream_records(handle):
                if isinstance(record, Message):
                    channel = channels.get(record.channel_id)
                    if channel is None:
                        continue
                    if first is None:
                        first = record.log_time
                    last = record.log_time
                    count += 1  # every topic: the truncation line says where the file ends, whatever was selected
                    if wanted is None or channel[0] in wanted:
                        yield BagMessage(channel[0], channel[1], record.data, record.log_time)
                elif isinstance(record, Schema):
                    schemas[record.id] = record.name
                elif isinstance(record, Channel):
                    channels[record.id] = (record.topic, schemas.get(record.schema_id, ""))
        except Truncated:
            raise BagError(f"{path}: truncated after {count} messages at {span_text(first, last)}") from None
    finally:
        handle.close()
