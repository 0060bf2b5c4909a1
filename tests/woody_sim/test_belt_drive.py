"""The compiled belt drive against the plain numpy formula, and the drive's physical limits."""

from __future__ import annotations

import numpy as np
import pytest

from woody_sim.belt_drive import belt_drive

DT = 1.0 / 480.0
SPEED = 0.508
MU_STATIC, MU_DYNAMIC = 0.8, 0.6


def numpy_drive(segments, contacts, velocity, masses, blend, normal_force):
    """The formula as plain numpy (what line_world computed before it was compiled)."""
    n = len(masses)
    normal_force = normal_force * (1.0 - blend)
    force = np.bincount(segments, contacts[:, 2], n)
    nx = -np.bincount(segments, contacts[:, 2] * contacts[:, 0], n)
    nz = -np.bincount(segments, contacts[:, 2] * contacts[:, 1], n)
    touched = np.unique(segments)
    normal_force[touched] += blend * force[touched]
    norm = np.hypot(nx[touched], nz[touched])
    touched, norm = touched[norm > 0.0], norm[norm > 0.0]
    normal = np.column_stack([nx[touched] / norm, np.zeros(len(touched)), nz[touched] / norm])
    slip = velocity[touched] - np.array([SPEED, 0.0, 0.0])
    slip -= np.sum(slip * normal, axis=1)[:, None] * normal
    drive = np.zeros((n, 3))
    drive[touched] = -(masses[touched] / DT)[:, None] * slip
    size = np.linalg.norm(drive, axis=1)
    sliding = size > MU_STATIC * normal_force
    drive[sliding] *= (MU_DYNAMIC * normal_force[sliding] / size[sliding])[:, None]
    return drive, normal_force


def run(segments, contacts, velocity, masses, blend=0.2, normal_force=None):
    n = len(masses)
    normal_force = np.zeros(n) if normal_force is None else normal_force.copy()
    drive = np.full((n, 3), np.nan)  # every row must be written
    belt_drive(np.asarray(segments, dtype=np.int64), np.asarray(contacts, dtype=float), velocity, masses, SPEED, DT,
               blend, MU_STATIC, MU_DYNAMIC, normal_force, drive)
    return drive, normal_force


def test_matches_the_numpy_formula_on_random_contacts() -> None:
    rng = np.random.default_rng(0)
    for _ in range(200):
        n, m = 40, int(rng.integers(1, 160))
        segments = rng.integers(0, n, m)
        tilt = rng.uniform(-0.4, 0.4, m)
        contacts = np.column_stack([np.sin(tilt), -np.cos(tilt), rng.uniform(0.0, 20.0, m)])
        velocity = rng.normal(SPEED, 0.02, (n, 3))
        masses = rng.uniform(0.01, 1.0, n)
        before = rng.uniform(0.0, 10.0, n)
        drive, normal_force = run(segments, contacts, velocity, masses, normal_force=before)
        expected_drive, expected_force = numpy_drive(segments, contacts, velocity, masses, 0.2, before)
        assert normal_force == pytest.approx(expected_force, rel=1e-14, abs=0.0)
        assert drive == pytest.approx(expected_drive, rel=1e-12, abs=1e-12)


def test_a_segment_at_belt_speed_gets_no_drive_and_one_without_contact_lets_go() -> None:
    velocity = np.array([[SPEED, 0.0, 0.0], [SPEED, 0.0, 0.0]])
    drive, normal_force = run([0], [[0.0, -1.0, 5.0]], velocity, np.array([0.5, 0.5]), blend=1.0,
                              normal_force=np.array([0.0, 3.0]))
    assert np.all(drive == 0.0)
    assert normal_force.tolist() == [5.0, 0.0]  # segment 1 lost its contact: N decays (blend 1: at once)


def test_slow_segment_is_pulled_up_to_speed_until_the_coulomb_cap() -> None:
    masses = np.array([0.5])
    slow = np.array([[SPEED - 0.001, 0.0, 0.0]])
    drive, _ = run([0], [[0.0, -1.0, 100.0]], slow, masses, blend=1.0)
    assert drive[0] == pytest.approx([0.5 / DT * 0.001, 0.0, 0.0])  # m (V - v) / dt, under 0.8 x 100 N
    stuck = np.array([[0.0, 0.0, 0.0]])
    drive, _ = run([0], [[0.0, -1.0, 100.0]], stuck, masses, blend=1.0)
    assert drive[0] == pytest.approx([MU_DYNAMIC * 100.0, 0.0, 0.0])  # over the static cap: slides at mu_d N


def test_on_the_roller_only_the_tangential_part_pulls() -> None:
    angle = 0.5  # on the roller's front, its outward normal tilted forward by this much
    contacts = [[-np.sin(angle), -np.cos(angle), 50.0]]  # from the fillet into the roller
    drive, _ = run([0], contacts, np.zeros((1, 3)), np.array([0.01]), blend=1.0)
    outward = np.array([np.sin(angle), 0.0, np.cos(angle)])
    tangent = np.array([np.cos(angle), 0.0, -np.sin(angle)])  # forward and down the roller
    assert drive[0] @ outward == pytest.approx(0.0, abs=1e-12)
    assert drive[0] == pytest.approx(0.01 / DT * SPEED * np.cos(angle) * tangent)
