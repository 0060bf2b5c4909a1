"""The spawn point's room: footprints, their overlap, and a fillet waiting until the belt has carried the last away."""

from __future__ import annotations

import numpy as np
import pytest

from woody_sim.spawn_clearance import SpawnClearance, footprint, overlap_area


def square(x: float, y: float, half: float = 0.05) -> np.ndarray:
    corners = np.array([[-half, -half, 0.0], [half, -half, 0.01], [half, half, 0.0], [-half, half, 0.02]])
    return footprint(corners, x, y)


def test_a_footprint_is_the_hull_seen_from_above_at_its_place_on_the_belt():
    corners = np.array([[-0.05, -0.05, 0.0], [0.05, -0.05, 0.01], [0.05, 0.05, 0.0], [-0.05, 0.05, 0.02]])
    inside = np.array([[0.0, 0.0, 0.03], [0.01, -0.02, 0.0]])
    shape = footprint(np.vstack([corners, inside]), -1.0, 0.2)
    assert len(shape) == 4 and shape[:, 0].min() == pytest.approx(-1.05) and shape[:, 1].max() == pytest.approx(0.25)


def test_overlap_is_the_shared_area_and_touching_shares_none():
    assert overlap_area(square(0, 0), square(0.05, 0)) == pytest.approx(0.05 * 0.1, rel=1e-4)
    assert overlap_area(square(0, 0), square(0.1, 0)) == pytest.approx(0.0, abs=1e-9)
    assert overlap_area(square(0, 0), square(0.3, 0.3)) == 0.0


def test_a_fillet_waits_until_the_belt_has_carried_its_neighbours_footprint_clear():
    clearance = SpawnClearance(reach_m=0.1)
    clearance.lay(square(-1.0, 0.0))
    beside = square(-1.0, 0.08)  # the next lane's fillet, 2 cm into this one
    assert not clearance.clear(beside)
    clearance.advance(0.05)
    assert not clearance.clear(beside)
    clearance.advance(0.05)  # carried a whole footprint along: only touching now
    assert clearance.clear(beside) and clearance.clear(square(-1.0, 0.2))


def test_a_footprint_longer_than_the_reach_widens_it():
    clearance = SpawnClearance(reach_m=0.1)
    clearance.lay(square(-1.0, 0.0, half=0.1))  # 0.2 m long: the reach grows to it, so it is not forgotten early
    assert clearance.reach_m == pytest.approx(0.2)
    clearance.advance(0.1)
    assert not clearance.clear(square(-1.0, 0.0))
    clearance.advance(0.05)
    assert clearance.clear(square(-1.0, 0.0))
    with pytest.raises(ValueError, match="reach"):
        SpawnClearance(reach_m=0.0)
