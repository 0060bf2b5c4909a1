"""woody_vision.frame_pairing: nearest colour frame within the tolerance, colour before or after its depth frame,
drops counted with their reason, a colour frame used once, out-of-order colour, the measured interval."""

from __future__ import annotations

import random

import pytest

from woody_vision.frame_pairing import COLOR_FRAMES_KEPT, HELD_DEPTH_FRAMES, FramePairing

MS = 1_000_000
PERIOD = 33_333_333
"""A 30 Hz camera's frame interval (ns)."""


def pairs(out) -> list[tuple]:
    return [(p.depth, p.color) for p in out]


def test_the_same_stamp_pairs_at_once_whichever_frame_comes_first():
    pairing = FramePairing()  # interval not measured yet: an exact stamp needs none
    assert pairing.add_color(0, "c0") == []
    assert pairs(pairing.add_depth(0, "d0")) == [("d0", "c0")]
    assert pairing.add_depth(PERIOD, "d1") == []
    assert pairs(pairing.add_color(PERIOD, "c1")) == [("d1", "c1")]
    assert pairing.dropped == 0


def test_a_depth_frame_waits_for_a_colour_frame_stamped_after_it():
    pairing = FramePairing(0.0167)
    assert pairing.add_depth(0, "d0") == []
    assert pairs(pairing.add_color(16 * MS, "c0")) == [("d0", "c0")]


def test_a_colour_frame_before_the_depth_frame_is_taken_once_the_next_colour_shows_none_is_nearer():
    pairing = FramePairing(0.0167)
    pairing.add_color(-10 * MS, "c0")
    assert pairing.add_depth(0, "d0") == []  # a colour frame at +5 ms could still come
    assert pairs(pairing.add_color(PERIOD - 10 * MS, "c1")) == [("d0", "c0")]


def test_the_nearest_colour_frame_within_the_tolerance_wins():
    pairing = FramePairing(0.0167)
    for stamp, name in ((-15 * MS, "c-15"), (-4 * MS, "c-4"), (6 * MS, "c6"), (15 * MS, "c15")):
        pairing.add_color(stamp, name)
    assert pairs(pairing.add_depth(0, "d0")) == [("d0", "c-4")]


def test_a_depth_frame_without_colour_within_the_tolerance_is_dropped_counted_and_says_how_far_the_nearest_was():
    pairing = FramePairing(0.0167)
    pairing.add_color(-20 * MS, "c0")
    (pair,) = pairing.add_color(25 * MS, "c1") + pairing.add_depth(0, "d0")
    assert (pair.depth, pair.color, pairing.dropped) == ("d0", None, 1)
    assert pair.reason == "no colour frame within ±16.7 ms of the depth frame (nearest was 20.0 ms away)"


def test_without_any_colour_every_depth_frame_is_answered_after_at_most_the_held_frames():
    pairing = FramePairing()
    answered = []
    for i in range(10):
        answered += pairing.add_depth(i * PERIOD, f"d{i}")
        assert len(answered) == max(0, i + 1 - HELD_DEPTH_FRAMES)
    assert [p.depth for p in answered] == [f"d{i}" for i in range(10 - HELD_DEPTH_FRAMES)]
    assert all(p.color is None for p in answered) and pairing.dropped == len(answered)
    assert answered[0].reason == "no colour frame within ±16.7 ms of the depth frame (none received)"


def test_a_colour_frame_is_never_used_twice():
    pairing = FramePairing(0.0167)
    pairing.add_color(8 * MS, "c")
    assert pairs(pairing.add_depth(0, "d0")) == [("d0", "c")]
    out = pairing.add_depth(15 * MS, "d1") + pairing.add_color(40 * MS, "c2")
    assert pairs(out) == [("d1", None)] and pairing.dropped == 1


def test_colour_frames_arriving_out_of_order_still_pair_by_nearest_stamp():
    pairing = FramePairing(0.0167)
    pairing.add_color(PERIOD + 2 * MS, "c1")
    pairing.add_color(2 * MS, "c0")
    assert pairs(pairing.add_depth(0, "d0") + pairing.add_depth(PERIOD, "d1")) == [("d0", "c0"), ("d1", "c1")]


def test_the_tolerance_is_half_the_depth_streams_median_step_and_a_lost_frame_does_not_move_it():
    pairing = FramePairing()
    assert pairing.tolerance_ns is None
    stamps = [0, PERIOD, 2 * PERIOD, 4 * PERIOD, 5 * PERIOD]  # the fourth frame lost
    for stamp in stamps:
        pairing.add_depth(stamp, "d")
    assert pairing.tolerance_ns == pytest.approx(PERIOD / 2, abs=1)
    pairing.clear()
    assert pairing.tolerance_ns is None and pairing.add_depth(0, "d") == []
    assert FramePairing(0.005).tolerance_ns == 5 * MS


def test_old_colour_frames_are_let_go():
    pairing = FramePairing(0.0167)
    for i in range(COLOR_FRAMES_KEPT + 1):
        pairing.add_color(i * PERIOD, f"c{i}")
    out = pairing.add_depth(0, "d0") + pairing.add_depth(COLOR_FRAMES_KEPT * PERIOD, "d1")
    assert pairs(out) == [("d0", None), ("d1", f"c{COLOR_FRAMES_KEPT}")]


@pytest.mark.parametrize("offset_ms", [-16, -10, 0, 1, 10, 16])
@pytest.mark.parametrize("seed", range(3))
def test_a_shifted_colour_stream_pairs_every_depth_frame_with_its_own_colour_frame_in_order(offset_ms, seed):
    """A 30 Hz camera, colour stamps shifted by ``offset_ms``, each frame's colour and depth arriving in either
    order with up to half a frame of latency between them; the tolerance is measured."""
    rng = random.Random(seed)
    arrivals = []
    for i in range(60):
        depth, color = i * PERIOD, i * PERIOD + offset_ms * MS
        arrivals += [(depth + rng.uniform(0, PERIOD / 2), "depth", depth, f"{i}"),
                     (max(depth, color) + rng.uniform(0, PERIOD / 2), "color", color, f"{i}")]
    pairing = FramePairing()
    out = []
    for _, stream, stamp, name in sorted(arrivals):
        add = pairing.add_depth if stream == "depth" else pairing.add_color
        out += add(stamp, name)
    assert [p.depth for p in out] == [f"{i}" for i in range(len(out))] and len(out) >= 60 - HELD_DEPTH_FRAMES
    assert [p.color for p in out] == [p.depth for p in out] and pairing.dropped == 0
