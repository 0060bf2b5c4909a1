"""Side frames: all while a fillet is in view and shortly after, one per idle period otherwise."""

from __future__ import annotations

import pytest

from woody_sim.side_gate import SideFrameGate


def test_frames_pass_while_occupied_then_a_tail_then_at_the_idle_rate():
    gate = SideFrameGate(idle_period_s=0.5, tail_frames=3)
    dt = 1 / 60
    occupied = [False] * 60 + [True] * 30 + [False] * 90  # empty second, half a second with a fillet, empty again
    taken = [i for i, occ in enumerate(occupied) if gate.take(occ, i * dt)]
    assert taken[:3] == [0, 1, 2]  # the start: the background
    assert [i for i in taken if i < 60] == [0, 1, 2, 32]  # then one per 0.5 s after the last one
    assert all(i in taken for i in range(60, 93))  # the passage and 3 frames after it
    assert [i for i in taken if i >= 93] == [122, 152]


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="idle_period_s"):
        SideFrameGate(0.0)
