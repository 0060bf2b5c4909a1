"""The hinge law's per-step arithmetic as compiled kernels: hinge state from link states, backward-Euler torques.

Kept apart from ``line_world`` so that what runs for every fillet at every
physics step (a few hundred flops and two small linear solves) runs without
Python overhead; the formulation and its validation are in docs/physics.md
("Hinge spring-damper").
"""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def hinge_state(state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hinge angles and rates (N - 1,) from segment states (N, 13); positive = downstream pitches down.

    Rows are [position, quaternion (x, y, z, w), linear, angular velocity] of
    each link's centre-of-mass frame, as ``LineWorld`` reads them every step;
    hinge i turns link i + 1 about link i's +y axis. Equal to pybullet's
    ``getJointStates`` up to round-off, without a query per fillet.
    """
    n = state.shape[0] - 1
    theta, rate = np.empty(n), np.empty(n)
    for i in range(n):
        ax, ay, az, aw = -state[i, 3], -state[i, 4], -state[i, 5], state[i, 6]
        bx, by, bz, bw = state[i + 1, 3], state[i + 1, 4], state[i + 1, 5], state[i + 1, 6]
        rel_y = aw * by - ax * bz + ay * bw + az * bx  # conj(parent) * child, its y and w parts
        rel_w = aw * bw - ax * bx - ay * by - az * bz
        angle = 2.0 * math.atan2(rel_y, rel_w)
        theta[i] = (angle + math.pi) % (2.0 * math.pi) - math.pi
        qx, qy, qz, qw = state[i, 3], state[i, 4], state[i, 5], state[i, 6]
        axis_x, axis_y, axis_z = 2.0 * (qx * qy - qw * qz), 1.0 - 2.0 * (qx * qx + qz * qz), 2.0 * (qy * qz + qw * qx)
        rate[i] = ((state[i + 1, 10] - state[i, 10]) * axis_x + (state[i + 1, 11] - state[i, 11]) * axis_y
                   + (state[i + 1, 12] - state[i, 12]) * axis_z)
    return theta, rate


@numba.njit(cache=True, nogil=True)
def implicit_hinge_torque(mass: np.ndarray, theta: np.ndarray, rate: np.ndarray, prev_rate: np.ndarray,
                          prev_torque: np.ndarray, k: float, damping: float, dt: float) -> np.ndarray:
    """Hinge torque tau = -k theta' - c theta_dot' evaluated at the end of the step (backward Euler).

    ``mass`` is a (6 + n, 6 + n) mass matrix of a floating-base chain with n
    hinges in any base coordinates (:func:`chain_mass_matrix`; pybullet's only for a
    body in a world that has removed none, see :func:`chain_mass_matrix`).
    With the base eliminated (Schur complement) it is S, and
    theta_dot' = theta_dot + dt S^-1 (tau + tau_ext). tau_ext, every other
    torque on the hinges (contacts, drive, limits), is observed from the
    previous step as S (theta_dot - prev_rate) / dt - prev_torque (zero when
    ``prev_torque`` is empty: the chain's first step). Solving
    (S + dt D) tau = S (-k theta - D theta_dot) - dt D tau_ext with D = c + k dt
    keeps even the lightest tip segment stable.
    """
    n = theta.shape[0]
    base = np.ascontiguousarray(mass[:6, :6])
    schur = np.ascontiguousarray(mass[6:, 6:]) - np.ascontiguousarray(mass[6:, :6]) @ np.linalg.solve(
        base, np.ascontiguousarray(mass[:6, 6:]))
    if prev_torque.shape[0] == n:
        external = schur @ ((rate - prev_rate) / dt) - prev_torque
    else:
        external = np.zeros(n)
    d = damping + k * dt
    rhs = schur @ (-k * theta - d * rate) - dt * d * external
    return np.linalg.solve(schur + dt * d * np.eye(n), rhs)


@numba.njit(cache=True, nogil=True)
def _add_spatial_inertia(out: np.ndarray, mass: float, com: np.ndarray, inertia: np.ndarray) -> None:
    """Add to ``out`` (6 x 6) the inertia about the origin, for spatial velocities [omega; v_origin], of a body
    of ``mass`` at ``com`` with rotational inertia ``inertia`` (3 x 3 about its COM, world axes)."""
    x, y, z = com[0], com[1], com[2]
    cx = ((0.0, -z, y), (z, 0.0, -x), (-y, x, 0.0))
    for r in range(3):
        for c in range(3):
            out[r, c] += inertia[r, c] - mass * (cx[r][0] * cx[0][c] + cx[r][1] * cx[1][c] + cx[r][2] * cx[2][c])
            out[r, 3 + c] += mass * cx[r][c]
            out[3 + r, c] -= mass * cx[r][c]
        out[3 + r, 3 + r] += mass


@numba.njit(cache=True, nogil=True)
def _rotation(q: np.ndarray) -> np.ndarray:
    """3 x 3 rotation of a unit quaternion (x, y, z, w)."""
    x, y, z, w = q[0], q[1], q[2], q[3]
    return np.array([
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
        [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
        [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
    ])


@numba.njit(cache=True, nogil=True)
def chain_mass_matrix(state: np.ndarray, masses: np.ndarray, inertias: np.ndarray,
                      joint_offsets: np.ndarray) -> np.ndarray:
    """(6 + n) x (6 + n) mass matrix of a floating chain of n + 1 links joined by n hinges about +y.

    ``state`` holds each link's centre-of-mass pose and velocity (N, 13) as
    ``LineWorld`` reads it, ``inertias`` the principal inertias (N, 3) along
    the link axes, ``joint_offsets`` (n, 3) the vector from hinge i to the
    centre of link i + 1 in that link's frame. Composite rigid bodies, O(n^2):
    M[j, k] = s_j . C_k s_k for j <= k, with s_j the hinge's spatial axis and
    C_k the spatial inertia of everything beyond hinge k. The first six
    coordinates are the base's spatial velocity [omega; v] at its centre of
    mass; pybullet's ``calculateMassMatrix`` uses other base coordinates, which
    changes that block but not the joint-space inertia with the base eliminated
    (what the hinge law uses). Computed from the chain's own state, never from
    pybullet's: ``calculateMassMatrix`` keeps the model it built for a body, and
    a chain built after another was removed can inherit it (docs/physics.md).
    """
    links = state.shape[0]
    n = links - 1
    origin = state[0, :3]
    out = np.zeros((6 + n, 6 + n))
    composite = np.zeros((6, 6))
    axes = np.zeros((n, 6))
    forces = np.zeros((n, 6))
    inertia = np.zeros((3, 3))
    hinge = np.zeros(3)
    for i in range(links - 1, -1, -1):
        rot = _rotation(state[i, 3:7])
        for r in range(3):
            for c in range(3):
                inertia[r, c] = (rot[r, 0] * inertias[i, 0] * rot[c, 0] + rot[r, 1] * inertias[i, 1] * rot[c, 1]
                                 + rot[r, 2] * inertias[i, 2] * rot[c, 2])
        _add_spatial_inertia(composite, masses[i], state[i, :3] - origin, inertia)
        if i == 0:
            break
        j = i - 1  # the hinge this link hangs from: composite now holds everything beyond it
        for r in range(3):
            hinge[r] = state[i, r] - origin[r] - (rot[r, 0] * joint_offsets[j, 0] + rot[r, 1] * joint_offsets[j, 1]
                                                   + rot[r, 2] * joint_offsets[j, 2])
            axes[j, r] = rot[r, 1]
        axes[j, 3] = hinge[1] * rot[2, 1] - hinge[2] * rot[1, 1]
        axes[j, 4] = hinge[2] * rot[0, 1] - hinge[0] * rot[2, 1]
        axes[j, 5] = hinge[0] * rot[1, 1] - hinge[1] * rot[0, 1]
        for r in range(6):
            total = 0.0
            for c in range(6):
                total += composite[r, c] * axes[j, c]
            forces[j, r] = total
            out[r, 6 + j] = total
            out[6 + j, r] = total
    out[:6, :6] = composite
    for k in range(n):
        for j in range(k + 1):
            value = 0.0
            for r in range(6):
                value += axes[j, r] * forces[k, r]
            out[6 + j, 6 + k] = value
            out[6 + k, 6 + j] = value
    return out
