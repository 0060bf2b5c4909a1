"""The soak's worker side and summary: a share of the fillet passages per worker process, merged into one figure.

The conditions and the blow-up test are :mod:`woody_sim.soak`'s; `woody soak`
(:mod:`woody_tools.commands.soak`) splits the passages over worker processes, each
with its own seed, so the workers cover different parts of the condition grid.
"""

from __future__ import annotations

import multiprocessing as mp

from woody_sim.line_world import calibrated_config
from woody_sim.meshes import conversions_noted, load_mesh_set
from woody_sim.soak import soak

DEFAULT_MESHES = "builtin,generated:3:5"


def work(args: tuple[str, int, int, mp.Queue]) -> dict:
    """One worker's share of the passages: (mesh spec, passages, seed, progress queue) -> its summary."""
    spec, passages, seed, queue = args
    with conversions_noted():  # `woody soak` said them
        meshes, _ = load_mesh_set(spec)
    return soak(meshes, passages, seed=seed, config=calibrated_config(), progress=queue.put).as_dict()


def merge(parts: list[dict]) -> dict:
    """One summary from the workers' summaries."""
    return {"passages": sum(p["passages"] for p in parts), "blowups": sum(p["blowups"] for p in parts),
            "worst_segment_speed_mps": max(p["worst_segment_speed_mps"] for p in parts),
            "sim_s": sum(p["sim_s"] for p in parts),
            "failed_conditions": [c for p in parts for c in p["failed_conditions"]]}
