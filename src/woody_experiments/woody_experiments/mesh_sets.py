"""The named mesh sets of the experiments and how a spec (builtin, generated:N[:SEED], a folder...) becomes meshes.

The sweep's default set and the calibration's sets are disjoint: the threshold
is chosen on one set and reported on another.
"""

from __future__ import annotations

import functools
import sys

from woody_sim.meshes import checked_mesh_set

DEFAULT_MESHES = "builtin,generated:24:1"
"""`woody sweep`'s 30 meshes; generated seeds 10000+ are disjoint from the calibration set."""
CALIBRATION_MESHES = "generated:8:9"
"""Calibration set (generated seeds 90000-90007).

The sweep's default meshes (builtin, seeds 0-2 and 10000+) are disjoint from it."""
TEST_MESHES = "generated:8:8"
"""Disjoint held-out set for the threshold's classification report (seeds 80000-80007)."""
LOO_MESHES = "builtin"
"""`woody calibrate --loo` uses the reference (non-generated) meshes of this set."""


def load_meshes(spec: str, program: str) -> dict:
    """The meshes of ``spec`` by name; each file skipped or converted is one stderr line ``<program>: ...``, said
    once per process however often a step asks for the set; ValueError (one line) when none is usable."""
    return dict(_loaded(spec, program))


@functools.cache
def _loaded(spec: str, program: str) -> dict:
    meshes, notes = checked_mesh_set(spec)
    for note in notes:
        print(f"{program}: {note}", file=sys.stderr)
    return {mesh.name: mesh for mesh in meshes}  # a name repeats only for the same source ("builtin,builtin")
