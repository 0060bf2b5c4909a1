"""The compiled hinge-law kernels against their plain numpy formulas and the law's two limits."""

from __future__ import annotations

import numpy as np
import pybullet as p
import pytest
from scipy.spatial.transform import Rotation

from woody_sim.hinge_law import chain_mass_matrix, hinge_state, implicit_hinge_torque
from woody_sim.line_geometry import LineGeometry
from woody_sim.line_world import LineWorld, calibrated_config, segment_inertias
from woody_sim.meshes import BUILTIN_DIR, load_mesh

DT = 1.0 / 480.0


def chain_state(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 13) link states of a chain pitching about y, with a small random yaw and roll on every link."""
    state = np.zeros((n, 13))
    pitch = np.cumsum(rng.uniform(-0.4, 0.4, n))
    euler = np.column_stack([rng.uniform(-0.05, 0.05, n), pitch, rng.uniform(-0.05, 0.05, n)])
    state[:, 3:7] = Rotation.from_euler("xyz", euler).as_quat()  # scipy's order is pybullet's (x, y, z, w)
    state[:, 7:13] = rng.normal(0.0, 2.0, (n, 6))
    return state


def test_hinge_state_is_the_relative_pitch_and_the_rate_about_the_parent_axis() -> None:
    rng = np.random.default_rng(3)
    state = chain_state(rng, 12)
    theta, rate = hinge_state(state)
    rot = Rotation.from_quat(state[:, 3:7])
    relative = (rot[:-1].inv() * rot[1:]).as_quat()
    expected_theta = 2.0 * np.arctan2(relative[:, 1], relative[:, 3])
    expected_theta = (expected_theta + np.pi) % (2.0 * np.pi) - np.pi
    parent_y = rot[:-1].apply([0.0, 1.0, 0.0])
    expected_rate = np.einsum("ij,ij->i", state[1:, 10:13] - state[:-1, 10:13], parent_y)
    assert theta == pytest.approx(expected_theta, abs=1e-12)
    assert rate == pytest.approx(expected_rate, abs=1e-12)


def floating_mass_matrix(rng: np.random.Generator, n: int, scale: np.ndarray) -> np.ndarray:
    """A symmetric positive definite (6 + n) mass matrix whose hinge block has the given diagonal scale."""
    root = rng.normal(0.0, 1.0, (6 + n, 6 + n)) * np.sqrt(np.concatenate([np.ones(6), scale]))[:, None]
    return root @ root.T + np.diag(np.concatenate([np.ones(6), scale]))


def numpy_torque(mass, theta, rate, prev_rate, prev_torque, k, c):
    schur = mass[6:, 6:] - mass[6:, :6] @ np.linalg.solve(mass[:6, :6], mass[:6, 6:])
    external = schur @ ((rate - prev_rate) / DT) - prev_torque if prev_torque.size else np.zeros_like(theta)
    d = c + k * DT
    rhs = schur @ (-k * theta - d * rate) - DT * d * external
    return np.linalg.solve(schur + DT * d * np.eye(len(theta)), rhs)


def test_implicit_torque_matches_the_formula_with_and_without_a_previous_step() -> None:
    rng = np.random.default_rng(5)
    n = 9
    mass = floating_mass_matrix(rng, n, np.full(n, 1e-3))
    theta, rate, prev_rate, prev_torque = (rng.normal(0.0, s, n) for s in (0.1, 2.0, 2.0, 0.5))
    for prev in (prev_torque, np.zeros(0)):
        got = implicit_hinge_torque(mass, theta, rate, prev_rate, prev, 100.0, 0.2, DT)
        assert got == pytest.approx(numpy_torque(mass, theta, rate, prev_rate, prev, 100.0, 0.2), rel=1e-9, abs=1e-12)


def test_implicit_torque_is_the_spring_on_heavy_hinges_and_balances_the_load_on_light_ones() -> None:
    rng = np.random.default_rng(7)
    n, k, c = 5, 100.0, 0.2
    theta, rate = rng.normal(0.0, 0.1, n), rng.normal(0.0, 1.0, n)
    heavy = floating_mass_matrix(rng, n, np.full(n, 1e4))
    spring = -k * theta - (c + k * DT) * rate
    assert implicit_hinge_torque(heavy, theta, rate, rate, np.zeros(0), k, c, DT) == pytest.approx(spring, rel=1e-3)
    light = floating_mass_matrix(rng, n, np.full(n, 1e-9))
    load = rng.normal(0.0, 1.0, n)  # what held the hinges still over the last step, against prev_torque = -load
    torque = implicit_hinge_torque(light, theta, rate, rate, -load, k, c, DT)
    assert torque == pytest.approx(-load, rel=1e-3)  # a massless tip: the hinge torque carries the load


def base_eliminated(mass: np.ndarray) -> np.ndarray:
    return mass[6:, 6:] - mass[6:, :6] @ np.linalg.solve(mass[:6, :6], mass[:6, 6:])


def test_chain_mass_matrix_gives_pybullets_joint_space_inertia_on_a_bent_chain() -> None:
    config = calibrated_config()
    with LineWorld(LineGeometry(spawn_x=-0.15), config) as world:
        fid = world.spawn(load_mesh(BUILTIN_DIR / "seed0002.obj"), 0.0, 1, 20.0, 0.508)
        while not world.is_dynamic(fid) or abs(world.hinge_angles(fid)).sum() < 0.5:  # well over the roller
            world.step()
        fillet = world._fillets[fid]
        model = fillet.model
        theta = world.hinge_angles(fid)
        rows = p.calculateMassMatrix(fillet.body, theta.tolist(), physicsClientId=fillet.physics.client)
        ours = chain_mass_matrix(fillet.state, model.masses, segment_inertias(model, config.inertia_floor),
                                 model.box_centers[1:] - model.joint_positions)
    expected = base_eliminated(np.array(rows))
    assert np.abs(base_eliminated(ours) - expected).max() < 1e-10 * np.abs(expected).max()
