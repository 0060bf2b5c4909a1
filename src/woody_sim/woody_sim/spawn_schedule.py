"""Which fillet enters which lane when: a seeded, reproducible spawn plan."""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np

from woody_sim.meshes import FilletMesh


class SpawnSchedule:
    """Every ``interval_s`` one fillet enters each lane.

    As in the paper, the lanes of one spawn event carry the same mesh side by
    side (so lane effects are measured on identical shapes); meshes cycle in
    order and each fillet's stiffness is drawn from ``k_values`` with ``seed``.
    """

    def __init__(self, meshes: Sequence[FilletMesh], k_values: Sequence[float], lanes: int, interval_s: float,
                 seed: int = 0, first_at: float = 0.0) -> None:
        if not meshes:
            raise ValueError("a spawn schedule needs at least one mesh")
        if not k_values:
            raise ValueError("a spawn schedule needs at least one stiffness value")
        if interval_s <= 0:
            raise ValueError(f"spawn interval must be > 0 s, got {interval_s}")
        self.meshes = list(meshes)
        self.k_values = [float(k) for k in k_values]
        self.lanes = lanes
        self.interval_s = float(interval_s)
        self.next_time = float(first_at)
        self.events = 0
        self._rng = np.random.default_rng(seed)

    def due(self, now: float) -> Iterator[tuple[FilletMesh, float, int]]:
        """(mesh, k, lane) of every fillet whose spawn time has come by sim time ``now``."""
        while now + 1e-9 >= self.next_time:
            mesh = self.meshes[self.events % len(self.meshes)]
            ks = self._rng.choice(self.k_values, size=self.lanes)
            self.events += 1
            self.next_time += self.interval_s
            for lane in range(self.lanes):
                yield mesh, float(ks[lane]), lane
