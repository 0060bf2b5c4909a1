"""Writing a bag the rosbag2 way: profile ``ros2``, ``ros2msg`` schemas, ``cdr`` messages, crash-tolerant chunks.

Channels carry rosbag2's ``offered_qos_profiles`` (`woody_bag.qos`) and ``topic_type_hash`` metadata; a closed
bag ends with rosbag2's ``rosbag2`` metadata record (its ``BagMetadata`` as YAML, version 9), which ``ros2 bag
info`` and rosbag2's MCAP plugin read.
Crash tolerance: messages are grouped in zstd-compressed chunks that go to the
operating system as soon as they are complete (no user-space buffering), and
`BagWriter.flush` closes the current chunk early. A process killed with SIGKILL
loses only the chunk in memory (`woody_bag.recovery` rescues the rest).
"""

from __future__ import annotations

import json
import os
import threading
import time
from pathlib import Path
from typing import Any

import mcap.writer as _mcap_writer
import yaml
from mcap.writer import CompressionType, IndexType, Writer

from woody_bag.errors import BagError
from woody_bag.schemas import message_definition, normalize_type, type_hash

DEFAULT_CHUNK_SIZE = 4 * 1024 * 1024
LIBRARY = "woody_bag"
ROSBAG2_RECORD = "rosbag2"
"""The metadata record rosbag2's MCAP plugin writes and reads: ``serialized_metadata`` (BagMetadata YAML)."""
ROSBAG2_METADATA_VERSION = 9
ROS_DISTRO = "jazzy"
_COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE,
                "": CompressionType.NONE}


class _LeveledZstd:
    """Stands in for the ``zstandard`` module inside ``mcap.writer`` so a `BagWriter` picks its level.

    ``mcap.writer.Writer`` compresses chunks with ``zstandard.compress(data)`` (level 3:
    ~130 MB/s on camera-noise images here, too slow for 200 Hz side-camera frames);
    level 1 compresses the same frames at ~700 MB/s to nearly the same size. A
    `BagWriter` sets its compressor for the calling thread around every writer call;
    any other user of ``mcap.writer`` in the process keeps the module's default.
    """

    def __init__(self, module: Any) -> None:
        self._module = module
        self.local = threading.local()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._module, name)

    def compress(self, data: bytes, *args: Any, **kwargs: Any) -> bytes:
        compressor = getattr(self.local, "compressor", None)
        if compressor is None or args or kwargs:
            return self._module.compress(data, *args, **kwargs)
        return compressor.compress(data)


if _mcap_writer.zstandard is not None and not isinstance(_mcap_writer.zstandard, _LeveledZstd):
    _mcap_writer.zstandard = _LeveledZstd(_mcap_writer.zstandard)
_ZSTD = _mcap_writer.zstandard


class _UnbufferedFile:
    """What `mcap.writer.Writer` needs of a stream, writing straight to the file descriptor.

    The writer hands over whole records (a chunk, its message indexes), so every
    complete chunk is in the operating system's hands at once and survives SIGKILL.
    """

    def __init__(self, path: Path, overwrite: bool) -> None:
        flags = os.O_WRONLY | os.O_CREAT | (os.O_TRUNC if overwrite else os.O_EXCL)
        self._fd = os.open(path, flags, 0o644)
        self._pos = 0

    def write(self, data: bytes | bytearray | memoryview) -> int:
        """Write one record whole; on an error (a full disk, a file size limit) cut the file back to the end of
        the last whole record, so the file holds no half record and the space of the partial write is free."""
        view = memoryview(data)
        total = len(view)
        try:
            while view:
                written = os.write(self._fd, view)
                view = view[written:]
        except OSError:
            os.ftruncate(self._fd, self._pos)
            os.lseek(self._fd, self._pos, os.SEEK_SET)
            raise
        self._pos += total
        return total

    def tell(self) -> int:
        return self._pos

    def flush(self) -> None:
        pass

    def fsync(self) -> None:
        os.fsync(self._fd)

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


class BagWriter:
    """An MCAP bag being written: `add_topic`, `write`, `flush`, `close` (also a context manager).

    Not thread-safe: call it from one thread. ``compression`` is ``zstd``, ``lz4`` or
    ``none``; ``metadata`` (values that are not strings are stored as JSON) is written
    at once as the metadata record ``woody`` (plus ``library`` and ``created``), so it
    survives a crash; `add_metadata` adds more records. A file that exists is an
    error unless ``overwrite``. `write` takes the topic of an earlier `add_topic`.
    """

    def __init__(self, path: str | os.PathLike, *, chunk_size: int = DEFAULT_CHUNK_SIZE,
                 compression: str = "zstd", compression_level: int = 1,
                 metadata: dict[str, Any] | None = None, overwrite: bool = False) -> None:
        self.path = Path(path)
        if compression not in _COMPRESSION:
            raise BagError(f"{self.path}: unknown compression {compression!r} (zstd, lz4 or none)")
        self._compressor = None
        if compression == "zstd":
            if _ZSTD is None:
                raise BagError(f"{self.path}: zstd compression needs the 'zstandard' package")
            self._compressor = _ZSTD.ZstdCompressor(level=compression_level, write_content_size=True)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = _UnbufferedFile(self.path, overwrite)
        except FileExistsError:
            raise BagError(f"{self.path}: already exists (choose another output or remove it)") from None
        except OSError as exc:
            raise BagError(f"{self.path}: cannot create bag: {exc.strerror or exc}") from None
        self._writer = Writer(self._file, chunk_size=chunk_size, compression=_COMPRESSION[compression],
                              index_types=IndexType.ALL)
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._types: dict[str, str] = {}
        self._topic_metadata: dict[str, dict[str, str]] = {}
        self._span: list[int] = []  # [first log_time, last log_time] once a message is written
        self.counts: dict[str, int] = {}
        self.bytes_written = 0
        self._pending = 0
        self._closed = False
        info = {"library": LIBRARY, "created": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
        info.update({k: v if isinstance(v, str) else json.dumps(v) for k, v in (metadata or {}).items()})
        try:
            self._writer.start(profile="ros2", library=LIBRARY)
            self.add_metadata("woody", info)
        except OSError as exc:  # e.g. a full disk: nothing useful was written
            self._file.close()
            raise BagError(f"{self.path}: cannot write bag: {exc.strerror or exc}") from None

    # ------------------------------------------------------------------ topics and messages
    def add_topic(self, topic: str, type_name: str, qos_profile_yaml: str = "", definition: bytes | None = None,
                  topic_type_hash: str | None = None) -> int:
        """Register ``topic`` of ``type_name``; returns its channel id (idempotent per topic).

        ``definition`` and ``topic_type_hash`` are the schema text and type hash to store (default: this
        installation's ``ros2msg`` text and hash, empty when it has none), so a recovered bag keeps the ones it
        was recorded with.
        """
        if topic in self._channels:
            return self._channels[topic]
        full = normalize_type(type_name)
        schema_id = self._schemas.get(full)
        if schema_id is None:
            text = definition if definition is not None else message_definition(full).encode()
            schema_id = self._writer.register_schema(full, "ros2msg", text)
            self._schemas[full] = schema_id
        if topic_type_hash is None:
            try:
                topic_type_hash = type_hash(full)
            except LookupError:
                topic_type_hash = ""
        metadata = {"offered_qos_profiles": qos_profile_yaml, "topic_type_hash": topic_type_hash}
        channel_id = self._writer.register_channel(topic=topic, message_encoding="cdr", schema_id=schema_id,
                                                   metadata=metadata)
        self._topic_metadata[topic] = metadata
        self._channels[topic] = channel_id
        self._types[topic] = full
        self.counts[topic] = 0
        return channel_id

    @property
    def topics(self) -> dict[str, str]:
        return dict(self._types)

    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int | None = None,
              sequence: int = 0) -> None:
        """Append one serialized (CDR) message of a topic registered with `add_topic`."""
        channel_id = self._channels[topic]
        if _ZSTD is not None:
            _ZSTD.local.compressor = self._compressor
        self._writer.add_message(channel_id=channel_id, log_time=log_time_ns, data=data,
                                 publish_time=log_time_ns if publish_time_ns is None else publish_time_ns,
                                 sequence=sequence)
        self.counts[topic] += 1
        self.bytes_written += len(data)
        self._pending += 1
        if self._span:
            self._span[0], self._span[1] = min(self._span[0], log_time_ns), max(self._span[1], log_time_ns)
        else:
            self._span = [log_time_ns, log_time_ns]

    def add_metadata(self, name: str, data: dict[str, Any]) -> None:
        self._writer.add_metadata(name, {str(k): str(v) for k, v in data.items()})

    def flush(self, fsync: bool = False) -> None:
        """Close the chunk in progress (if it has messages) and hand it to the OS."""
        if self._pending:
            if _ZSTD is not None:
                _ZSTD.local.compressor = self._compressor
            self._writer.flush()
            self._pending = 0
        if fsync:
            self._file.fsync()

    def close(self) -> None:
        """Write the last chunk, the summary and the indexes; close the file. Idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            if _ZSTD is not None:
                _ZSTD.local.compressor = self._compressor
            self.add_metadata(ROSBAG2_RECORD, {"serialized_metadata": self.rosbag2_metadata()})
            self._writer.finish()
        finally:
            self._file.close()

    def rosbag2_metadata(self) -> str:
        """rosbag2's ``BagMetadata`` of what was written so far, as the YAML its MCAP plugin stores."""
        start, end = self._span or [0, 0]
        count = sum(self.counts.values())
        topics = [{"topic_metadata": {"name": topic, "type": full, "serialization_format": "cdr",
                                      "offered_qos_profiles": self._topic_metadata[topic]["offered_qos_profiles"],
                                      "type_description_hash": self._topic_metadata[topic]["topic_type_hash"]},
                   "message_count": self.counts[topic]} for topic, full in self._types.items()]
        duration, starting = {"nanoseconds": end - start}, {"nanoseconds_since_epoch": start}
        return yaml.safe_dump({
            "version": ROSBAG2_METADATA_VERSION, "storage_identifier": "mcap", "duration": duration,
            "starting_time": starting, "message_count": count, "topics_with_message_count": topics,
            "compression_format": "", "compression_mode": "", "relative_file_paths": [self.path.name],
            "files": [{"path": self.path.name, "starting_time": starting, "duration": duration,
                       "message_count": count}],
            "custom_data": {}, "ros_distro": ROS_DISTRO}, sort_keys=False)

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
