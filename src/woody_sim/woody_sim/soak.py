"""Physics soak: many fillet passages over the roller, counting numerical blow-ups.

A passage is one fillet from activation at the belt edge until it leaves the
line (falls past ``remove_z``). The soak cycles through the conditions the
calibration and the line can produce, so a formulation that is stable only at
the default settings cannot pass it:

* stiffness k in SOAK_K, total mass M over SOAK_MASSES (the calibration's range),
* 100 and 130 FPM, 1 to 6 lanes, fillets side by side (all lanes cross the
  roller together) or staggered,
* built-in real meshes and generated ones,
* one wave of fillets per world, or several waves through the same world, as
  in a running line: later chains are built after earlier ones were removed,
  which is what once broke pybullet's cached mass matrices (docs/physics.md).

Each batch is one LineWorld with one condition; a blow-up is a segment faster
than ``BLOWUP_SPEED`` or a non-finite state (LineWorld removes such a fillet
and lists it in ``blown_up``). The worst segment speed over all passages is
reported too, so a near miss shows before it becomes a failure.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace

import numpy as np

from woody_common.line import PAPER_SPEEDS_FPM, REFERENCE_SPEED_FPM, fpm_to_mps
from woody_sim.frame_schedule import DUE_SLACK
from woody_sim.line_conditions import line_preset, place_mesh, placement_for
from woody_sim.line_geometry import LineGeometry
from woody_sim.line_world import LineWorld, PhysicsConfig
from woody_sim.meshes import FilletMesh
from woody_sim.split_world import SplitLineWorld

SOAK_K = (0.0, 10.0, 20.0, 40.0, 100.0, 200.0, 400.0)
SOAK_MASSES = (2.0, 10.0, 30.0, 100.0, 300.0)
"""kg: a decade either side of the calibrated masses (woody calibrate searches inside this range)."""
SOAK_SPEEDS_FPM = PAPER_SPEEDS_FPM
SOAK_LANES = (1, 3, 6)
SOAK_WAVES = (1, 3)
SPAWN_GAP_S = 0.25
"""Staggered batches spawn one fillet per lane this far apart (s)."""
WAVE_GAP_S = 1.0
"""A wave starts this long (s) after the previous one, when that one has mostly left the roller."""
BATCH_TIMEOUT_S = 12.0
FREE_FALL_MARGIN = 0.02
"""A passage ends once every segment is this far (m) below the roller's lowest point: no contact is left,
only the free fall, which the soak need not pay for."""


@dataclass(frozen=True)
class SoakCondition:
    """One batch: ``waves`` x ``lanes`` fillets of one mesh at one k, mass and speed, side by side or staggered."""

    mesh: int
    k: float
    mass: float
    speed_fpm: float
    lanes: int
    staggered: bool
    waves: int = 1

    def spawn_times(self) -> list[tuple[float, int]]:
        """(time s, lane) of every fillet of the batch, in time order."""
        return sorted((wave * WAVE_GAP_S + (lane * SPAWN_GAP_S if self.staggered else 0.0), lane)
                      for wave in range(self.waves) for lane in range(self.lanes))


@dataclass
class SoakResult:
    passages: int = 0
    blowups: int = 0
    worst_speed_mps: float = 0.0
    sim_s: float = 0.0
    wall_s: float = 0.0
    failures: list[SoakCondition] | None = None

    def as_dict(self) -> dict:
        return {"passages": self.passages, "blowups": self.blowups, "worst_segment_speed_mps": self.worst_speed_mps,
                "sim_s": self.sim_s, "wall_s": self.wall_s,
                "failed_conditions": [vars(c) for c in self.failures or []]}


def conditions(n_meshes: int, seed: int = 0) -> Iterator[SoakCondition]:
    """An endless shuffled cycle over the whole condition grid (reproducible from ``seed``)."""
    grid = list(itertools.product(range(n_meshes), SOAK_K, SOAK_MASSES, SOAK_SPEEDS_FPM, SOAK_LANES, (False, True),
                                  SOAK_WAVES))
    rng = np.random.default_rng(seed)
    while True:
        for i in rng.permutation(len(grid)):
            yield SoakCondition(*grid[i])


def run_batch(condition: SoakCondition, mesh: FilletMesh,
              config: PhysicsConfig | None = None) -> tuple[int, int, float, float]:
    """Simulate one batch to the end; returns (passages, blow-ups, worst segment speed m/s, sim seconds)."""
    geometry = LineGeometry(lanes=condition.lanes, spawn_x=-0.15)
    geometry = replace(geometry, remove_z=-2.0 * geometry.roller_radius - FREE_FALL_MARGIN)
    speed = fpm_to_mps(condition.speed_fpm)
    worst = 0.0
    with LineWorld(geometry, config) as world:
        pending = condition.spawn_times()
        while (pending or world.fillets) and world.time < BATCH_TIMEOUT_S:
            while pending and world.time >= pending[0][0]:
                world.spawn(mesh, condition.k, pending.pop(0)[1], condition.mass, speed)
            world.step()
            for fid in world.fillets:
                if world.is_dynamic(fid):
                    worst = max(worst, float(np.abs(world.segment_velocities(fid)).max()))
            world.take_removed()
        return condition.lanes * condition.waves, len(world.blown_up), worst, world.time


def soak(meshes: list[FilletMesh], passages: int, seed: int = 0, config: PhysicsConfig | None = None,
         progress: Callable[[int], None] | None = None) -> SoakResult:
    """Run batches from :func:`conditions` until at least ``passages`` fillets have crossed the roller."""
    result = SoakResult(failures=[])
    wall0 = time.perf_counter()
    for condition in conditions(len(meshes), seed):
        if result.passages >= passages:
            break
        count, blown, worst, sim = run_batch(condition, meshes[condition.mesh], config)
        result.passages += count
        result.blowups += blown
        result.worst_speed_mps = max(result.worst_speed_mps, worst)
        result.sim_s += sim
        if blown:
            result.failures.append(condition)
        if progress is not None:
            progress(count)
    result.wall_s = time.perf_counter() - wall0
    return result


SHIFT_SPACING_M = 0.45
"""In-lane spacing of the shift soak's line: the messy line's default (woody run)."""


SHIFT_FRAME_S = 1.0 / 30.0
"""The shift soak asks for every chain's pose this often, as line_sim's top camera does (a split world's workers
step towards each such request)."""


@dataclass
class ShiftResult:
    """A long messy line through one physics world or recycled workers: what its processes held as it ran."""

    fillets: int = 0
    blowups: int = 0
    sim_s: float = 0.0
    wall_s: float = 0.0
    rss_mb: list[tuple[int, float]] = field(default_factory=list)
    """(fillets gone, this process's resident memory MB) at every sample."""
    worker_rss_mb: list[tuple[int, float]] = field(default_factory=list)
    """(fillets gone, the largest resident memory MB of a physics worker then) at every sample (workers only)."""
    workers_started: int = 0


def shift(meshes: list[FilletMesh], fillets: int, mass: float, lanes: int = 3, speed_fpm: float = REFERENCE_SPEED_FPM,
          seed: int = 0, samples: int = 20, config: PhysicsConfig | None = None,
          progress: Callable[[int], None] | None = None, workers: int = 0, recycle_after: int = 0,
          on_sample: Callable[[ShiftResult], None] | None = None) -> ShiftResult:
    """Run ``fillets`` placed fillets of a messy line (each turned, sized and offset its own way, woody_sim.
    line_conditions) as line_sim does for hours: through one LineWorld in this process (``workers`` 0), or over
    ``workers`` physics worker processes, each replaced after ``recycle_after`` spawns (0: never; woody_sim.
    split_world). Samples the resident memory of this process and of the workers ``samples`` times as the
    fillets leave (``on_sample`` hears of each); each placed mesh is released once its fillet is gone, as
    line_sim does."""
    geometry = LineGeometry(lanes=lanes)
    speed = fpm_to_mps(speed_fpm)
    line = (line_preset("messy"), seed, mass)
    result = ShiftResult()
    placed: dict[int, FilletMesh] = {}
    every = max(1, fillets // samples)
    wall0, next_wave, spawned = time.perf_counter(), 0.0, 0
    world = (SplitLineWorld(geometry, config or PhysicsConfig(), workers, recycle_after=recycle_after) if workers
             else LineWorld(geometry, config))
    with world:
        while result.fillets < fillets:
            if world.time >= next_wave and spawned < fillets:
                spawned = _spawn_wave(world, meshes, line, spawned, speed, placed)
                next_wave += SHIFT_SPACING_M / speed
            _step_frame(world)
            for fillet_id in world.take_removed():
                world.release(placed.pop(fillet_id))
                result.fillets += 1
                if result.fillets % every == 0:
                    _sample_memory(world, result)
                    if on_sample is not None:
                        on_sample(result)
                if progress is not None:
                    progress(1)
        result.blowups, result.sim_s = len(world.blown_up), world.time
        result.workers_started = world.workers_started if isinstance(world, SplitLineWorld) else 0
    result.wall_s = time.perf_counter() - wall0
    return result


def _step_frame(world: LineWorld | SplitLineWorld) -> None:
    """Step to the next camera frame and take every pose there, as line_sim does."""
    until = world.time + SHIFT_FRAME_S
    world.plan(until)
    while world.time + DUE_SLACK < until:
        world.step()
    world.segment_poses()


def _sample_memory(world: LineWorld | SplitLineWorld, result: ShiftResult) -> None:
    result.rss_mb.append((result.fillets, resident_mb()))
    pids = world.worker_pids if isinstance(world, SplitLineWorld) else []
    if pids:
        result.worker_rss_mb.append((result.fillets, max(resident_mb(pid) for pid in pids)))


def _spawn_wave(world: LineWorld | SplitLineWorld, meshes: list[FilletMesh], line: tuple, spawned: int, speed: float,
                placed: dict[int, FilletMesh]) -> int:
    """One fillet per lane, each placed its own way (``line``: the conditions, seed and mass M); returns the
    fillets spawned so far."""
    conditions, seed, mass = line
    for lane in range(world.geometry.lanes):
        placement = placement_for(conditions, seed, spawned)
        mesh = place_mesh(meshes[spawned % len(meshes)], placement)
        k = SOAK_K[spawned % len(SOAK_K)]
        fillet_id = world.spawn(mesh, k, lane, mass * placement.scale ** 3, speed,
                                lateral_offset=placement.lateral_offset_m)
        placed[fillet_id] = mesh
        spawned += 1
    return spawned


def resident_mb(pid: int | str = "self") -> float:
    """A process's resident memory (MB, Linux /proc; NaN elsewhere or once it has ended): this one by default."""
    try:
        with open(f"/proc/{pid}/status") as status:
            return next(int(line.split()[1]) / 1024.0 for line in status if line.startswith("VmRSS"))
    except (OSError, StopIteration):
        return math.nan


def growth_mb_per_1000(samples: list[tuple[int, float]]) -> float:
    """The least-squares slope of resident memory over the second half of the samples (MB per 1,000 fillets): the
    first half holds the start-up (caches, the first worlds)."""
    late = samples[len(samples) // 2:]
    if len(late) < 2:
        return math.nan
    x, y = np.array(late, dtype=float).T
    return float(np.polyfit(x, y, 1)[0] * 1000.0)
