"""woody_common.stamps: the one stamp <-> seconds conversion stays a valid builtin_interfaces/Time."""

import pytest

from woody_common.stamps import nanoseconds_to_stamp, seconds_to_stamp, stamp_to_nanoseconds, stamp_to_seconds


@pytest.mark.parametrize("seconds", [0.0, 1.5, 12.345678901, 1e6 + 0.25])
def test_seconds_round_trip_to_the_nanosecond(seconds):
    assert stamp_to_seconds(seconds_to_stamp(seconds)) == pytest.approx(seconds, abs=1e-9)


def test_rounding_up_to_a_whole_second_carries_into_sec():
    stamp = seconds_to_stamp(1.9999999999)
    assert (stamp.sec, stamp.nanosec) == (2, 0)


def test_negative_times_clamp_to_zero():
    assert (seconds_to_stamp(-0.5).sec, seconds_to_stamp(-0.5).nanosec) == (0, 0)
    assert (nanoseconds_to_stamp(-1).sec, nanoseconds_to_stamp(-1).nanosec) == (0, 0)


def test_nanoseconds_are_exact():
    ns = 1_700_000_000_123_456_789
    assert stamp_to_nanoseconds(nanoseconds_to_stamp(ns)) == ns
