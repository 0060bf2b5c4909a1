"""The errors of woody_bag: `BagError` for the caller, `Truncated` where a file's readable part ends."""

from __future__ import annotations


class BagError(Exception):
    """A bag that cannot be (fully) read or written; the message is one line naming the file."""


class Truncated(Exception):
    """Raised by `woody_bag.records.stream_records` where a file stops being readable (cut short or damaged)."""
