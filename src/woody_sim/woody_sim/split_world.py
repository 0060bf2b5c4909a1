"""Physics on several cores: the fillets are simulated in worker processes, each spawn where the load is least.

line_sim is bound by its physics: one core steps every chain while the others mostly idle. Fillets never touch
one another (belt and roller are static), so a fillet moves the same in whichever pybullet world it is:
:class:`SplitLineWorld` keeps a :class:`~woody_sim.line_world.LineWorld` in this process and one in each of
``workers`` worker processes, and gives every spawn to the world with the fewest live fillets. The lanes of a
line spawn together, so their crossings of the roller, the expensive part, are spread over the worlds as evenly
as the counts allow; on a tie a worker wins, since this process also publishes the frames.

The workers step on their own between pose requests: :meth:`SplitLineWorld.plan` tells them the sim time of
the next one, all worlds step at once until then, and :meth:`SplitLineWorld.segment_poses` at that step waits
for each worker. Spawns reach a worker a few steps late and are placed where the belt has carried them since
(exact: a fillet moves analytically until it nears the roller). Fillets a worker removes are reported with its
poses, so :meth:`SplitLineWorld.take_removed` names them after the next pose request. A belt speed change is
sent to every world before a worker can have passed its step, so all apply it at the same step.
"""

from __future__ import annotations

import multiprocessing.connection as mpc
import os
import traceback
from typing import Any

import numpy as np

from woody_sim.child_process import ChildProcess, parent_messages
from woody_sim.fillet_model import FilletModel
from woody_sim.frame_schedule import DUE_SLACK
from woody_sim.line_geometry import LineGeometry
from woody_sim.line_world import LineWorld, PhysicsConfig, check_fillet_id, check_lateral_offset, check_spawn
from woody_sim.meshes import FilletMesh

MAX_PHYSICS_WORKERS = 64
"""The most worker processes a SplitLineWorld starts; :func:`check_workers` also caps them at the core count."""


def check_workers(workers: int) -> int:
    """``workers`` if this machine has a core for each (more only add switching), else ValueError."""
    cores = os.cpu_count() or 1
    if not 1 <= workers <= min(cores, MAX_PHYSICS_WORKERS):
        raise ValueError(f"physics workers must be 1..{min(cores, MAX_PHYSICS_WORKERS)} (the cores of this "
                         f"machine), got {workers}")
    return workers


class _Worker:
    """One worker process, and what this process knows of its world."""

    def __init__(self, index: int, geometry: LineGeometry, config: PhysicsConfig, start_method: str,
                 timeout: float) -> None:
        self.process = ChildProcess(_serve, (geometry, config), f"physics worker {index}", start_method, timeout)
        self.models: dict[int, FilletModel] = {}
        """Live fillets of this worker and their chain models."""
        self.meshes: set[int] = set()
        """Keys of the meshes (and chain models) sent to this worker."""
        self.poses: dict[int, np.ndarray] = {}
        self.asked = self.reached = 0  # the step the worker was last sent to, and the step it answered from

    def send_to(self, step: int) -> None:
        if step > self.asked:
            self.process.send(("advance", step))
            self.asked = step

    def wait_for(self, step: int, removed: list[int], blown: list[int]) -> None:
        """Take answers until the worker has reached ``step``; its removals and blow-ups go to the lists."""
        self.send_to(step)
        while self.reached < step:
            answer = self.process.recv()
            if answer[0] != "at":
                raise RuntimeError(f"{self.process.name} failed:\n{answer[1]}")
            _, self.reached, gone, blew, self.poses = answer
            for fillet_id in gone:
                del self.models[fillet_id]
            removed += gone
            blown += blew


class SplitLineWorld:
    """The part of :class:`~woody_sim.line_world.LineWorld`'s interface line_sim uses, over a world in this
    process and one in each of ``workers`` processes."""

    def __init__(self, geometry: LineGeometry, config: PhysicsConfig, workers: int = 1, start_method: str = "spawn",
                 timeout: float = 30.0) -> None:
        if config.activation_margin is None:
            raise ValueError("SplitLineWorld needs fillets that start on the belt (activation_margin set)")
        check_workers(workers)
        self.geometry, self.config = geometry, config
        self._local = LineWorld(geometry, config)
        self._workers: list[_Worker] = []
        try:
            for index in range(workers):
                self._workers.append(_Worker(index, geometry, config, start_method, timeout))
        except BaseException:
            self.close()
            raise
        self._mesh_keys: dict[FilletMesh, int] = {}
        self._removed: list[int] = []
        self._blown: list[int] = []
        self._next_id = self._next_key = 0

    @property
    def time(self) -> float:
        return self._local.time

    @property
    def steps(self) -> int:
        return self._local.steps

    @property
    def blown_up(self) -> list[int]:
        """Ids of fillets removed because their chain blew up, in every world."""
        return self._local.blown_up + self._blown

    def model_for(self, mesh: FilletMesh) -> FilletModel:
        """The chain geometry for a mesh, built here once; a worker gets it with the mesh at its first spawn of it
        (so this process never waits for a worker still starting)."""
        if mesh not in self._mesh_keys:
            self._mesh_keys[mesh] = self._next_key  # never a released mesh's key: the workers forgot it
            self._next_key += 1
        return self._local.model_for(mesh)

    def _send_mesh(self, worker: _Worker, mesh: FilletMesh) -> int:
        """The mesh's key, the mesh and its chain model sent to ``worker`` first if it has not had them."""
        model = self.model_for(mesh)
        key = self._mesh_keys[mesh]
        if key not in worker.meshes:
            worker.process.send(("mesh", key, mesh, model))
            worker.meshes.add(key)
        return key

    def _broadcast(self, msg: tuple) -> None:
        for worker in self._workers:
            worker.process.send(msg)

    def release(self, mesh: FilletMesh) -> None:
        """As :meth:`LineWorld.release <woody_sim.line_world.LineWorld.release>`, in every world."""
        self._local.release(mesh)
        key = self._mesh_keys.pop(mesh, None)
        for worker in self._workers:
            if key in worker.meshes:
                worker.meshes.discard(key)
                worker.process.send(("release", key))

    def change_speed(self, speed_mps: float, at_time: float | None = None) -> None:
        """As :meth:`LineWorld.change_speed <woody_sim.line_world.LineWorld.change_speed>`; ``at_time`` may
        not come before a step a worker has been sent on to (call it before :meth:`plan` passes it)."""
        at = self.time if at_time is None else float(at_time)
        asked = max(w.asked for w in self._workers)
        if at < asked * self.config.dt - 1e-9:
            raise ValueError(f"the physics workers may have stepped past {at} s already (up to "
                             f"{asked * self.config.dt} s): change the belt speed earlier")
        self._local.change_speed(speed_mps, at)
        self._broadcast(("speed", float(speed_mps), at))

    def spawn(self, mesh: FilletMesh, k: float, lane: int, mass: float, speed_mps: float,
              fillet_id: int | None = None, lateral_offset: float = 0.0) -> int:
        """As :meth:`LineWorld.spawn <woody_sim.line_world.LineWorld.spawn>`, in the world with the fewest live
        fillets."""
        k, lane, mass, speed = check_spawn(self.geometry, k, lane, mass, speed_mps)
        lateral_offset = check_lateral_offset(lateral_offset)
        live = self._local.fillets.keys() | set().union(*(w.models for w in self._workers))
        fillet_id = check_fillet_id(self._next_id if fillet_id is None else fillet_id, live)
        worker = self._least_loaded()
        if worker is None:
            self._local.spawn(mesh, k, lane, mass, speed, fillet_id, lateral_offset=lateral_offset)
        else:
            key = self._send_mesh(worker, mesh)
            worker.send_to(self.steps)  # the worker must have reached the spawn's step when it reads it
            worker.process.send(("spawn", self.steps, key, k, lane, mass, speed, fillet_id, lateral_offset))
            worker.models[fillet_id] = self._local.model_for(mesh).with_mass(mass)
        self._next_id = max(self._next_id, fillet_id + 1)
        return fillet_id

    def _least_loaded(self) -> _Worker | None:
        """The worker with the fewest live fillets, or None for this process's world when it has fewer still."""
        worker = min(self._workers, key=lambda w: len(w.models))
        if len(self._local.fillets) < len(worker.models):
            return None
        return worker

    def model(self, fillet_id: int) -> FilletModel:
        for worker in self._workers:
            if fillet_id in worker.models:
                return worker.models[fillet_id]
        return self._local.model(fillet_id)

    def step(self) -> float:
        """Step this process's world (the workers step on their own towards the planned step)."""
        return self._local.step()

    def plan(self, until: float) -> None:
        """The next :meth:`segment_poses` comes at the first step at or after sim time ``until``: start the
        workers on the steps up to it."""
        dt = self.config.dt
        step = max(self.steps, int(until / dt) - 1)
        while step * dt + DUE_SLACK < until:  # the test FrameSchedule uses for a camera being due
            step += 1
        for worker in self._workers:
            worker.send_to(step)

    def segment_poses(self) -> dict[int, np.ndarray]:
        """Every live fillet's (N, 7) segment poses now; waits for the workers to reach this step."""
        asked = max(w.asked for w in self._workers)
        if asked > self.steps:
            raise RuntimeError(f"poses asked at step {self.steps}, but the workers were sent on to {asked}")
        poses = self._local.segment_poses()
        for worker in self._workers:
            worker.wait_for(self.steps, self._removed, self._blown)
            poses.update(worker.poses)
        return poses

    def take_removed(self) -> list[int]:
        """Ids removed since the last call; the workers' as of the last :meth:`segment_poses`."""
        removed, self._removed = self._local.take_removed() + self._removed, []
        return removed

    def close(self) -> None:
        for worker in self._workers:
            worker.process.close()
        self._local.close()

    def __enter__(self) -> SplitLineWorld:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _serve(conn: mpc.Connection, geometry: LineGeometry, config: PhysicsConfig) -> None:
    """The worker: a LineWorld that spawns, steps and answers as the parent says."""
    world = LineWorld(geometry, config)
    meshes: dict[int, FilletMesh] = {}
    try:
        for msg in parent_messages(conn, b"woody-physics"):
            try:
                answer = _obey(world, meshes, msg)
            except Exception:  # noqa: BLE001 - reported to the parent, which raises it
                answer = ("err", traceback.format_exc())
            if answer is not None:
                try:
                    conn.send(answer)
                except (BrokenPipeError, ConnectionResetError):  # the parent died mid-request: nobody to answer
                    return
    finally:
        world.close()


def _obey(world: LineWorld, meshes: dict[int, FilletMesh], msg: tuple) -> tuple[Any, ...] | None:
    op = msg[0]
    if op == "mesh":
        _, key, mesh, model = msg
        meshes[key] = mesh
        world.model_for(mesh, model)
    elif op == "spawn":
        _, step, key, k, lane, mass, speed, fillet_id, offset = msg
        world.spawn(meshes[key], k, lane, mass, speed, fillet_id, spawn_time=step * world.config.dt,
                    lateral_offset=offset)
    elif op == "speed":
        world.change_speed(msg[1], msg[2])
    elif op == "release":
        world.release(meshes.pop(msg[1]))
    elif op == "advance":
        removed, blown_before = [], len(world.blown_up)
        while world.steps < msg[1]:
            world.step()
            removed += world.take_removed()
        return ("at", world.steps, removed, world.blown_up[blown_before:], world.segment_poses())
    else:
        raise ValueError(f"unknown request {op!r}")
    return None
