"""MCAP bags the rosbag2 way, without rosbag2: schemas, a crash-tolerant writer, a tolerant reader.

Files written here use profile ``ros2``, schema encoding ``ros2msg`` (the message's
``.msg`` text plus every nested definition, as rosbag2 writes it) and message
encoding ``cdr``; channels carry rosbag2's ``offered_qos_profiles`` metadata. They
open with ``mcap``/``mcap_ros2``, ``rosbags`` (``AnyReader`` on the bare file),
Foxglove and ``ros2 bag`` with the MCAP storage plugin.

Crash tolerance: messages are grouped in zstd-compressed chunks that go to the
operating system as soon as they are complete (no user-space buffering), and
`BagWriter.flush` closes the current chunk early. A process killed with SIGKILL
loses only the chunk in memory; `read_bag` reads every complete chunk of such a
file and then raises `BagError` saying where the file stops.

No rclpy node code here: only ``rclpy.serialization`` for `decode`.
"""

from __future__ import annotations

import functools
import importlib
import io
import json
import os
import re
import sys
import threading
import time
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any, NamedTuple

import mcap.writer as _mcap_writer
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, DataEnd, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType, IndexType, Writer

__all__ = [
    "BagError",
    "BagMessage",
    "BagWriter",
    "DEFAULT_CHUNK_SIZE",
    "bag_metadata",
    "bag_summary",
    "bag_topics",
    "decode",
    "message_class",
    "message_definition",
    "normalize_type",
    "parse_qos_profiles",
    "qos_profiles_yaml",
    "read_bag",
    "recover_bag",
]

SEPARATOR = "=" * 80
DEFAULT_CHUNK_SIZE = 4 * 1024 * 1024
MCAP_MAGIC = b"\x89MCAP0\r\n"
LIBRARY = "woody_tools.mcap_io"

_PRIMITIVES = {
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
    "int32", "uint32", "int64", "uint64", "string", "wstring",
}
_COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE,
                "": CompressionType.NONE}


class BagError(Exception):
    """A bag that cannot be (fully) read or written; the message is one line naming the file."""


class BagMessage(NamedTuple):
    topic: str
    type_name: str
    data: bytes
    log_time: int


# --------------------------------------------------------------------------- types and schemas

def normalize_type(type_name: str) -> str:
    """``pkg/msg/Type`` for ``pkg/msg/Type`` or ``pkg/Type``."""
    parts = type_name.strip().split("/")
    if len(parts) == 2 and all(parts):
        return f"{parts[0]}/msg/{parts[1]}"
    if len(parts) == 3 and all(parts):
        return type_name.strip()
    raise ValueError(f"not a ROS message type name: {type_name!r}")


def _prefixes() -> list[Path]:
    prefixes = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    for extra in (sys.prefix, sys.base_prefix):
        if Path(extra) not in prefixes:
            prefixes.append(Path(extra))
    return prefixes


@functools.cache
def _msg_text(pkg: str, name: str) -> str:
    for prefix in _prefixes():
        candidate = prefix / "share" / pkg / "msg" / f"{name}.msg"
        if candidate.is_file():
            return candidate.read_text()
    raise LookupError(f"no {pkg}/msg/{name}.msg under share/ of {os.pathsep.join(map(str, _prefixes()))}")


def _dependencies(pkg: str, text: str) -> list[str]:
    """Complex field types of one .msg text as ``pkg/Type``, sorted."""
    deps: set[str] = set()
    for line in text.splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        base = re.sub(r"\[[^\]]*\]$", "", line.split()[0])
        base = re.split(r"<=", base)[0]
        if base in _PRIMITIVES:
            continue
        parts = base.split("/")
        if len(parts) == 1:
            deps.add(f"{pkg}/{parts[0]}")
        else:
            deps.add(f"{parts[0]}/{parts[-1]}")
    return sorted(deps)


@functools.cache
def message_definition(type_name: str) -> str:
    """rosbag2's ``ros2msg`` schema text of ``type_name`` (``pkg/msg/Type`` or ``pkg/Type``)."""
    pkg, _, name = normalize_type(type_name).split("/")
    root = _msg_text(pkg, name)
    written = {f"{pkg}/{name}"}
    blocks: list[str] = [root]

    def visit(dep_pkg: str, text: str) -> None:
        for dep in _dependencies(dep_pkg, text):
            if dep in written:
                continue
            written.add(dep)
            dpkg, dname = dep.split("/")
            dtext = _msg_text(dpkg, dname)
            blocks.append(f"{SEPARATOR}\nMSG: {dep}\n{dtext}")
            visit(dpkg, dtext)

    visit(pkg, root)
    return "\n".join(blocks)


@functools.cache
def message_class(type_name: str) -> type:
    """The Python class of ``pkg/msg/Type``; `LookupError` (one line) when it cannot be imported."""
    try:
        pkg, kind, name = normalize_type(type_name).split("/")
        module = importlib.import_module(f"{pkg}.{kind}")
        return getattr(module, name)
    except (ImportError, AttributeError, ValueError) as exc:
        raise LookupError(f"message type {type_name} is not importable: {exc}") from None


def decode(type_name: str, data: bytes) -> Any:
    """Deserialize CDR bytes of ``type_name`` into its rclpy message object."""
    from rclpy.serialization import deserialize_message

    return deserialize_message(data, message_class(type_name))


# --------------------------------------------------------------------------- QoS metadata

_INFINITE = (9223372036, 854775807)


def _enum_name(value: Any) -> str:
    name = getattr(value, "name", None)
    if name is None:
        return str(value).lower()
    return name.lower()


def _duration(value: Any) -> tuple[int, int]:
    ns = getattr(value, "nanoseconds", None)
    if ns is None or ns <= 0 or ns >= 2**63 - 1:
        return _INFINITE
    return ns // 1_000_000_000, ns % 1_000_000_000


def qos_profiles_yaml(profiles: Iterable[Any]) -> str:
    """rosbag2 (Jazzy) ``offered_qos_profiles`` YAML for rclpy `QoSProfile` objects."""
    out = []
    for qos in profiles:
        lines = [
            f"- history: {_enum_name(qos.history)}",
            f"  depth: {int(qos.depth)}",
            f"  reliability: {_enum_name(qos.reliability)}",
            f"  durability: {_enum_name(qos.durability)}",
        ]
        for key in ("deadline", "lifespan"):
            sec, nsec = _duration(getattr(qos, key, None))
            lines += [f"  {key}:", f"    sec: {sec}", f"    nsec: {nsec}"]
        lines.append(f"  liveliness: {_enum_name(qos.liveliness)}")
        sec, nsec = _duration(getattr(qos, "liveliness_lease_duration", None))
        lines += ["  liveliness_lease_duration:", f"    sec: {sec}", f"    nsec: {nsec}"]
        lines.append(f"  avoid_ros_namespace_conventions: {'true' if qos.avoid_ros_namespace_conventions else 'false'}")
        out.append("\n".join(lines))
    return "\n".join(out)


def parse_qos_profiles(text: str) -> list[dict[str, Any]]:
    """The profiles of an ``offered_qos_profiles`` string as dicts (enum names lower case)."""
    if not text or not text.strip():
        return []
    import yaml

    try:
        items = yaml.safe_load(text)
    except yaml.YAMLError:
        return []
    names = {
        "history": {0: "system_default", 1: "keep_last", 2: "keep_all", 3: "unknown"},
        "reliability": {0: "system_default", 1: "reliable", 2: "best_effort", 3: "unknown", 4: "best_available"},
        "durability": {0: "system_default", 1: "transient_local", 2: "volatile", 3: "unknown", 4: "best_available"},
    }
    result = []
    for item in items if isinstance(items, list) else []:
        if not isinstance(item, dict):
            continue
        for key, table in names.items():
            value = item.get(key)
            if isinstance(value, int):
                item[key] = table.get(value, "unknown")
            elif isinstance(value, str):
                item[key] = value.lower()
        result.append(item)
    return result


# --------------------------------------------------------------------------- writer

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
        view = memoryview(data)
        total = len(view)
        while view:
            written = os.write(self._fd, view)
            view = view[written:]
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
        self._writer.start(profile="ros2", library=LIBRARY)
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._types: dict[str, str] = {}
        self.counts: dict[str, int] = {}
        self.bytes_written = 0
        self._pending = 0
        self._closed = False
        info = {"library": LIBRARY, "created": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
        info.update({k: v if isinstance(v, str) else json.dumps(v) for k, v in (metadata or {}).items()})
        self.add_metadata("woody", info)

    # ------------------------------------------------------------------ topics and messages
    def add_topic(self, topic: str, type_name: str, qos_profile_yaml: str = "", definition: bytes | None = None) -> int:
        """Register ``topic`` of ``type_name``; returns its channel id (idempotent per topic).

        ``definition`` is the schema text to store (default: this installation's ``ros2msg``
        text), so a recovered bag keeps the schemas it was recorded with.
        """
        if topic in self._channels:
            return self._channels[topic]
        full = normalize_type(type_name)
        schema_id = self._schemas.get(full)
        if schema_id is None:
            text = definition if definition is not None else message_definition(full).encode()
            schema_id = self._writer.register_schema(full, "ros2msg", text)
            self._schemas[full] = schema_id
        channel_id = self._writer.register_channel(
            topic=topic, message_encoding="cdr", schema_id=schema_id,
            metadata={"offered_qos_profiles": qos_profile_yaml})
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
            self._writer.finish()
        finally:
            self._file.close()

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# --------------------------------------------------------------------------- reader

def _open(path: str | os.PathLike) -> tuple[Path, io.BufferedReader]:
    path = Path(path)
    if path.is_dir():
        found = sorted(path.glob("*.mcap"))
        if not found:
            raise BagError(f"{path}: directory holds no .mcap file")
        path = found[0]
    try:
        handle = open(path, "rb")
    except FileNotFoundError:
        raise BagError(f"{path}: no such file") from None
    except OSError as exc:
        raise BagError(f"{path}: cannot open: {exc.strerror or exc}") from None
    magic = handle.read(len(MCAP_MAGIC))
    if magic != MCAP_MAGIC:
        handle.close()
        if not magic:
            raise BagError(f"{path}: empty file, not an MCAP bag")
        if len(magic) < len(MCAP_MAGIC) and MCAP_MAGIC.startswith(magic):
            raise BagError(f"{path}: truncated after 0 messages at t=0.000s (cut inside the MCAP magic)")
        raise BagError(f"{path}: not an MCAP file")
    return path, handle


def _complete(handle: io.BufferedReader) -> bool:
    """True when the file ends with a footer and the closing magic."""
    size = handle.seek(0, io.SEEK_END)
    if size < 2 * len(MCAP_MAGIC) + 29:
        return False
    handle.seek(size - len(MCAP_MAGIC))
    if handle.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
        return False
    handle.seek(size - len(MCAP_MAGIC) - 29)
    opcode = handle.read(1)
    return opcode == b"\x02"


def _summary(path: Path, handle: io.BufferedReader):
    """The summary of a complete file with chunk indexes, else None."""
    if not _complete(handle):
        return None
    try:
        handle.seek(0)
        summary = SeekingReader(handle).get_summary()
    except Exception:  # noqa: BLE001 - a damaged footer means: read it as a stream
        return None
    if summary is None or not summary.chunk_indexes:
        return None
    return summary


class _Truncated(Exception):
    pass


def _stream_records(handle: io.BufferedReader) -> Iterator[Any]:
    """Records of the data section in file order, chunks broken up; `_Truncated` where reading fails.

    Stops quietly at DataEnd/Footer (the summary is not needed). A chunk cut short
    (its data shorter than declared, or not decompressing) counts as the end.
    """
    try:
        for record in StreamReader(handle, emit_chunks=True, record_size_limit=2**32).records:
            if isinstance(record, Chunk):
                if record.compression == "" and len(record.data) != record.uncompressed_size:
                    raise _Truncated()
                yield from list(breakup_chunk(record, validate_crc=True))
            elif isinstance(record, (DataEnd, Footer)):
                return
            else:
                yield record
    except _Truncated:
        raise
    except Exception:  # noqa: BLE001 - whatever the damage, the readable part ends here
        raise _Truncated() from None


def _seconds(first: int | None, last: int | None) -> str:
    if first is None or last is None:
        return "t=0.000s"
    return f"t={(last - first) / 1e9:.3f}s"


def read_bag(path: str | os.PathLike, topics: Iterable[str] | None = None) -> Iterator[BagMessage]:
    """Every message of the bag (or of ``topics``) as `BagMessage` (topic, type_name, data, log_time).

    A complete file is read through its summary in log-time order. A file without a
    summary (a killed recorder) is read as a stream in file order: everything readable
    is yielded, then `BagError` says ``"<path>: truncated after N messages at t=...s"``
    (N and t over every topic of the file, t from its first message). Missing file /
    not an MCAP: `BagError` at the first ``next()``.
    """
    path, handle = _open(path)
    wanted = None if topics is None else set(topics)
    count = 0
    first = last = None
    try:
        summary = _summary(path, handle)
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
                raise BagError(f"{path}: corrupt after {count} messages at {_seconds(first, last)} "
                               f"({type(exc).__name__}: {exc})".replace("\n", " ")) from None
            return
        handle.seek(0)
        schemas: dict[int, str] = {}
        channels: dict[int, tuple[str, str]] = {}
        try:
            for record in _stream_records(handle):
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
        except _Truncated:
            raise BagError(f"{path}: truncated after {count} messages at {_seconds(first, last)}") from None
    finally:
        handle.close()


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
    path, handle = _open(path)
    try:
        summary = _summary(path, handle)
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
        for record in _stream_records(handle):
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
    except _Truncated:
        result["error"] = f"{path}: truncated after {count} messages at {_seconds(start, end)}"
    result["message_count"] = count
    result["start_ns"] = start or 0
    result["end_ns"] = end or 0


def _schema_text(schema: Schema | None) -> str:
    return schema.data.decode(errors="replace") if schema is not None else ""


def bag_metadata(path: str | os.PathLike) -> dict[str, dict[str, str]]:
    """The bag's metadata records, e.g. ``{"woody": {...run info...}}``."""
    return bag_summary(path)["metadata"]


def recover_bag(source: str | os.PathLike, target: str | os.PathLike, *, overwrite: bool = False) -> dict[str, Any]:
    """Rewrite every complete chunk of ``source`` (e.g. a SIGKILLed recording) into a valid, indexed ``target``.

    Schemas, channels (with their QoS metadata), messages and metadata records are copied
    in file order; the ``woody.recover`` metadata record says what was recovered and where
    the source ended. Returns ``{"messages", "topics", "error"}`` (``error`` is the
    truncation line of the source, ``None`` when it was complete). `BagError` (one line)
    when the source is unreadable from the start or the target cannot be written.
    """
    path, handle = _open(source)
    if Path(target).resolve() == path.resolve():
        handle.close()
        raise BagError(f"{target}: the output must differ from the input")
    state: dict[str, Any] = {"writer": None, "metadata": {}, "schemas": {}, "channels": {}, "count": 0,
                             "first": None, "last": None}
    error = None
    try:
        handle.seek(0)
        try:
            for record in _stream_records(handle):
                _copy_record(record, state, target, overwrite)
        except _Truncated:
            error = f"{path}: truncated after {state['count']} messages at {_seconds(state['first'], state['last'])}"
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
                             definition=schema.data)
            state["channels"][record.id] = record.topic
    elif isinstance(record, Message) and record.channel_id in state["channels"]:
        writer.write(state["channels"][record.channel_id], record.data, record.log_time, record.publish_time,
                     record.sequence)
        state["first"] = record.log_time if state["first"] is None else state["first"]
        state["last"] = record.log_time
        state["count"] += 1
