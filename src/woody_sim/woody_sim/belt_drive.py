"""The seed system's belt drive as one compiled kernel per fillet and step.

Belt and roller are frictionless; each segment the conveyor touches is pulled
towards the belt velocity by F = m (V_line - v) / dt in the contact's tangent
plane, capped by Coulomb friction on its low-pass filtered normal force
(docs/physics.md, "Belt drive and friction"). It runs for every touching
segment at every physics step, so it is compiled like the hinge law.
"""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def belt_drive(segments: np.ndarray, contacts: np.ndarray, velocity: np.ndarray, masses: np.ndarray, speed: float,
               dt: float, blend: float, mu_static: float, mu_dynamic: float, normal_force: np.ndarray,
               drive: np.ndarray) -> None:
    """Filter each segment's normal force and set the drive (N, 3) on the segments in contact.

    ``segments`` (n,) and ``contacts`` (n, 3) are the fillet's conveyor contact
    points: segment index and [normal x, normal z, normal force (N)], the normal
    pointing from the fillet into the conveyor. A segment's contacts are summed
    (their force-weighted normals give its outward contact normal). V_line is
    ``speed`` along +x everywhere, as in the seed: on the roller only its
    projection on the tangent plane pulls, which shrinks as the roller curves
    down, so a segment is let go by geometry. A force above mu_static N is cut
    to mu_dynamic N (sliding). ``normal_force`` (N,) is updated in place, as
    N <- (1 - blend) N + blend * (this step's force); segments without contact
    get no drive.
    """
    n = masses.shape[0]
    force, nx, nz = np.zeros(n), np.zeros(n), np.zeros(n)
    touched = np.zeros(n, dtype=np.bool_)
    for row in range(segments.shape[0]):
        i = segments[row]
        touched[i] = True
        force[i] += contacts[row, 2]
        nx[i] -= contacts[row, 2] * contacts[row, 0]
        nz[i] -= contacts[row, 2] * contacts[row, 1]
    drive[:] = 0.0
    for i in range(n):
        normal_force[i] *= 1.0 - blend
        if not touched[i]:
            continue
        normal_force[i] += blend * force[i]
        norm = math.hypot(nx[i], nz[i])
        if norm <= 0.0:
            continue
        ux, uz = nx[i] / norm, nz[i] / norm
        sx, sy, sz = velocity[i, 0] - speed, velocity[i, 1], velocity[i, 2]
        along = sx * ux + sz * uz
        sx, sz = sx - along * ux, sz - along * uz
        rate = masses[i] / dt
        fx, fy, fz = -rate * sx, -rate * sy, -rate * sz
        size = math.sqrt(fx * fx + fy * fy + fz * fz)
        scale = 1.0
        if size > mu_static * normal_force[i]:
            scale = mu_dynamic * normal_force[i] / size
        drive[i, 0], drive[i, 1], drive[i, 2] = fx * scale, fy * scale, fz * scale
