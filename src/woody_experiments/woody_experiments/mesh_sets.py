"""The named mesh sets of the experiments and how a spec (builtin, generated:N[:SEED], a folder...) becomes meshes.

The sweep's default set and the calibration's sets are disjoint: the threshold
is chosen on one set and reported on another.
"""

from __future__ import annotations

import sys

from woody_sim.meshes import load_mesh_set

DEFAULT_MESHES = "builtin,generated:24:1"
"""`woody sweep`'s 30 meshes; generated seeds 10000+ are disjoint from the calibration set."""
CALIBRATION_MESHES = "generated:8:9"
"""Calibration set (generated seeds 90000-90007).

The sweep's default meshes (builtin, seeds 0-2 and 10000+) are disjoint from it."""
TEST_MESHES = "generated:8:8"
"""Disjoint held-out set for the threshold's classification report (seeds 80000-80007)."""
LOO_MESHES = "builtin"
"""`woody calibrate --loo` uses the reference (non-generated) meshes of this set."""


def load_meshes(spec: str) -> dict:
    """The meshes of ``spec`` by name (the first of a duplicated name); one stderr line per skipped mesh."""
    meshes, errors = load_mesh_set(spec)
    for error in errors:
        print(f"woody sweep: skipped mesh: {error}", file=sys.stderr)
    by_name = {}
    for mesh in meshes:
        by_name.setdefault(mesh.name, mesh)
    return by_name
