"""Opening an MCAP bag file and walking its records, for the reader, the summaries and the recovery.

A complete file (footer and closing magic, chunk indexes) is read through its
summary; a file without one (a killed recorder) is read as a stream of records in
file order, chunks broken up, until `Truncated` says where it stops.
"""

from __future__ import annotations

import io
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from mcap.reader import SeekingReader
from mcap.records import Chunk, DataEnd, Footer
from mcap.stream_reader import StreamReader, breakup_chunk

from woody_bag.errors import BagError, Truncated

MCAP_MAGIC = b"\x89MCAP0\r\n"


def open_bag(path: str | os.PathLike) -> tuple[Path, io.BufferedReader]:
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


def is_complete(handle: io.BufferedReader) -> bool:
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


def read_summary(path: Path, handle: io.BufferedReader):
    """The summary of a complete file: with chunk indexes, or with statistics of no message (a recording that
    ended before anything arrived), else None."""
    if not is_complete(handle):
        return None
    try:
        handle.seek(0)
        summary = SeekingReader(handle).get_summary()
    except Exception:  # noqa: BLE001 - a damaged footer means: read it as a stream
        return None
    if summary is None:
        return None
    empty = summary.statistics is not None and summary.statistics.message_count == 0
    return summary if summary.chunk_indexes or empty else None


def stream_records(handle: io.BufferedReader) -> Iterator[Any]:
    """Records of the data section in file order, chunks broken up; `Truncated` where reading fails.

    Stops quietly at DataEnd/Footer (the summary is not needed). A chunk cut short
    (its data shorter than declared, or not decompressing) counts as the end.
    """
    try:
        for record in StreamReader(handle, emit_chunks=True, record_size_limit=2**32).records:
            if isinstance(record, Chunk):
                if record.compression == "" and len(record.data) != record.uncompressed_size:
                    raise Truncated()
                yield from list(breakup_chunk(record, validate_crc=True))
            elif isinstance(record, (DataEnd, Footer)):
                return
            else:
                yield record
    except Truncated:
        raise
    except Exception:  # noqa: BLE001 - whatever the damage, the readable part ends here
        raise Truncated() from None


def span_text(first: int | None, last: int | None) -> str:
    if first is None or last is None:
        return "t=0.000s"
    return f"t={(last - first) / 1e9:.3f}s"
