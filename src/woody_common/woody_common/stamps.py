"""ROS time stamps <-> seconds and nanoseconds: the one conversion every woody node and tool uses.

A stamp's ``nanosec`` must stay in [0, 1e9) and its ``sec`` must not go negative
(builtin_interfaces/Time is unsigned); rounding a float like 1.9999999999 would
otherwise produce ``nanosec = 1_000_000_000`` and a message rclpy refuses, so
the conversion goes through whole nanoseconds and clamps below at 0.
"""

from __future__ import annotations

from builtin_interfaces.msg import Time

NS_PER_S = 1_000_000_000


def stamp_to_nanoseconds(stamp) -> int:
    """Whole nanoseconds of a stamp (exact, usable as a key)."""
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def nanoseconds_to_stamp(nanoseconds: int) -> Time:
    """A valid stamp for whole nanoseconds; negative times clamp to 0."""
    sec, nanosec = divmod(max(int(nanoseconds), 0), NS_PER_S)
    return Time(sec=sec, nanosec=nanosec)


def stamp_to_seconds(stamp) -> float:
    """Seconds of a stamp as a float."""
    return stamp.sec + stamp.nanosec * 1e-9


def seconds_to_stamp(seconds: float) -> Time:
    """A valid stamp for float seconds, rounded to the nearest nanosecond; negative times clamp to 0."""
    return nanoseconds_to_stamp(round(seconds * NS_PER_S))
