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

A line that runs for hours can recycle its workers (``recycle_after``): whatever a process keeps of the fillets
it has simulated (pybullet's memory of removed bodies, the allocator's fragmentation; docs/physics.md, "A whole
shift") ends with the process. A worker that has taken ``recycle_after`` spawns gets a successor, started at
once; the old one takes spawns until the successor has imported and answered, so the line never waits for a
process to start, then only steps its last fillets and ends once they are gone. The physics then runs in the
workers only: this process's world takes no spawns, since it cannot be replaced.
"""

from __future__ import annotations

import multiprocessing.connection as mpc
import traceback
from typing import Any

import numpy as np

from woody_common.line import physics_worker_limit
from woody_sim.child_process import ChildProcess, parent_messages
from woody_sim.fillet_model import FilletModel
from woody_sim.frame_schedule import DUE_SLACK
from woody_sim.line_geometry import LineGeometry
from woody_sim.line_world import (
    LineWorld,
    PhysicsConfig,
    check_fillet_id,
    check_lateral_offset,
    check_spawn,
    return_freed_memory,
)
from woody_sim.meshes import FilletMesh


def check_workers(workers: int) -> int:
    """``workers`` if this machine has a core for each (woody_common.line.physics_worker_limit), else ValueError."""
    limit = physics_worker_limit()
    if not 1 <= workers <= limit:
        raise ValueError(f"physics workers must be 1..{limit} (the cores of this machine), got {workers}")
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
        self.spawned = 0
        """Spawns this worker has taken (it is recycled after the world's ``recycle_after``)."""

    def start_at(self, step: int, speed_changes: list[tuple[float, float]]) -> None:
        """Start the worker's clock at ``step`` of a running line, with the belt speed changes still to come."""
        self.process.send(("start", step, speed_changes))
        self.asked = self.reached = step

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
    process and one in each of ``workers`` processes; ``recycle_after`` > 0 replaces each worker after that many
    spawns (module doc)."""

    def __init__(self, geometry: LineGeometry, config: PhysicsConfig, workers: int = 1, start_method: str = "spawn",
                 timeout: float = 30.0, recycle_after: int = 0) -> None:
        if config.activation_margin is None:
            raise ValueError("SplitLineWorld needs fillets that start on the belt (activation_margin set)")
        check_workers(workers)
        if recycle_after < 0:
            raise ValueError(f"recycle_after must be >= 0 spawns (0: never), got {recycle_after}")
        self.geometry, self.config = geometry, config
        self.recycle_after = int(recycle_after)
        self._start = (geometry, config, start_method, timeout)
        self._local = LineWorld(geometry, config)
        self._workers: list[_Worker] = []
        """The workers taking spawns."""
        self._successors: list[tuple[_Worker, _Worker]] = []
        """(worker, its successor still starting): the successor takes its place once it has answered."""
        self._retiring: list[_Worker] = []
        """Workers that take no more spawns; each ends once its last fillet is gone."""
        self._ending: list[_Worker] = []
        """Workers asked to end, closed once they have."""
        self._speed_changes: list[tuple[float, float]] = []
        """(sim time, speed) of every belt speed change asked for, for a worker that starts later."""
        self._started = 0
        try:
            for _ in range(workers):
                self._workers.append(self._new_worker())
        except BaseException:
            self.close()
            raise
        self._mesh_keys: dict[FilletMesh, int] = {}
        self._removed: list[int] = []
        self._blown: list[int] = []
        self._next_id = self._next_key = 0

    def _new_worker(self) -> _Worker:
        worker = _Worker(self._started, *self._start)
        self._started += 1
        return worker

    def _stepping(self) -> list[_Worker]:
        """The workers that hold fillets or may get them: they step with the line."""
        return self._workers + self._retiring

    @property
    def workers_started(self) -> int:
        """Worker processes started so far, successors included."""
        return self._started

    @property
    def worker_pids(self) -> list[int]:
        """Process ids of the workers that step with the line now."""
        return [w.process.pid for w in self._stepping() if w.process.pid is not None]

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
        for worker in self._stepping() + [successor for _, successor in self._successors]:
            worker.process.send(msg)

    def release(self, mesh: FilletMesh) -> None:
        """As :meth:`LineWorld.release <woody_sim.line_world.LineWorld.release>`, in every world."""
        self._local.release(mesh)
        key = self._mesh_keys.pop(mesh, None)
        for worker in self._stepping():
            if key in worker.meshes:
                worker.meshes.discard(key)
                worker.process.send(("release", key))

    def change_speed(self, speed_mps: float, at_time: float | None = None) -> None:
        """As :meth:`LineWorld.change_speed <woody_sim.line_world.LineWorld.change_speed>`; ``at_time`` may
        not come before a step a worker has been sent on to (call it before :meth:`plan` passes it)."""
        at = self.time if at_time is None else float(at_time)
        asked = max(w.asked for w in self._stepping())
        if at < asked * self.config.dt - 1e-9:
            raise ValueError(f"the physics workers may have stepped past {at} s already (up to "
                             f"{asked * self.config.dt} s): change the belt speed earlier")
        self._local.change_speed(speed_mps, at)
        self._speed_changes.append((at, float(speed_mps)))
        self._broadcast(("speed", float(speed_mps), at))

    def spawn(self, mesh: FilletMesh, k: float, lane: int, mass: float, speed_mps: float,
              fillet_id: int | None = None, lateral_offset: float = 0.0) -> int:
        """As :meth:`LineWorld.spawn <woody_sim.line_world.LineWorld.spawn>`, in the world with the fewest live
        fillets."""
        k, lane, mass, speed = check_spawn(self.geometry, k, lane, mass, speed_mps)
        lateral_offset = check_lateral_offset(lateral_offset)
        live = self._local.fillets.keys() | set().union(*(w.models for w in self._stepping()))
        fillet_id = check_fillet_id(self._next_id if fillet_id is None else fillet_id, live)
        self._take_up_successors()
        worker = self._least_loaded()
        if worker is None:
            self._local.spawn(mesh, k, lane, mass, speed, fillet_id, lateral_offset=lateral_offset)
        else:
            key = self._send_mesh(worker, mesh)
            worker.send_to(self.steps)  # the worker must have reached the spawn's step when it reads it
            worker.process.send(("spawn", self.steps, key, k, lane, mass, speed, fillet_id, lateral_offset))
            worker.models[fillet_id] = self._local.model_for(mesh).with_mass(mass)
            worker.spawned += 1
            if worker.spawned == self.recycle_after:
                self._start_successor(worker)
        self._next_id = max(self._next_id, fillet_id + 1)
        return fillet_id

    def _least_loaded(self) -> _Worker | None:
        """The worker with the fewest live fillets, or None for this process's world when it has fewer still (never
        when the workers are recycled)."""
        worker = min(self._workers, key=lambda w: len(w.models))
        if not self.recycle_after and len(self._local.fillets) < len(worker.models):
            return None
        return worker

    def _start_successor(self, worker: _Worker) -> None:
        """Start the process that will take ``worker``'s place, its clock at this step."""
        successor = self._new_worker()
        successor.start_at(self.steps, [c for c in self._speed_changes if c[0] >= self.time - 1e-9])
        self._successors.append((worker, successor))

    def _take_up_successors(self) -> None:
        """Every successor that has answered takes its worker's place; the worker retires."""
        for worker, successor in list(self._successors):
            if not successor.process.poll():
                continue
            answer = successor.process.recv()
            if answer[0] != "ready":
                raise RuntimeError(f"{successor.process.name} failed:\n{answer[1]}")
            self._successors.remove((worker, successor))
            self._workers[self._workers.index(worker)] = successor
            self._retiring.append(worker)

    def _end_emptied(self) -> None:
        """Ask each retiring worker whose last fillet is gone to end; close those that have ended."""
        for worker in [w for w in self._retiring if not w.models]:
            self._retiring.remove(worker)
            worker.process.send(("close",))
            self._ending.append(worker)
        for worker in [w for w in self._ending if not w.process.is_alive()]:
            self._ending.remove(worker)
            worker.process.close()
            return_freed_memory()  # the meshes and chain models this process built for its fillets

    def model(self, fillet_id: int) -> FilletModel:
        for worker in self._stepping():
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
        for worker in self._stepping():
            worker.send_to(step)

    def segment_poses(self) -> dict[int, np.ndarray]:
        """Every live fillet's (N, 7) segment poses now; waits for the workers to reach this step."""
        asked = max(w.asked for w in self._stepping())
        if asked > self.steps:
            raise RuntimeError(f"poses asked at step {self.steps}, but the workers were sent on to {asked}")
        poses = self._local.segment_poses()
        for worker in self._stepping():
            worker.wait_for(self.steps, self._removed, self._blown)
            poses.update(worker.poses)
        self._end_emptied()
        return poses

    def take_removed(self) -> list[int]:
        """Ids removed since the last call; the workers' as of the last :meth:`segment_poses`."""
        removed, self._removed = self._local.take_removed() + self._removed, []
        return removed

    def close(self) -> None:
        successors = [successor for _, successor in self._successors]
        for worker in self._workers + self._retiring + self._ending + successors:
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
    if op == "start":
        _, step, speed_changes = msg
        world.start_at(step)
        for at, speed in speed_changes:
            world.change_speed(speed, at)
        return ("ready",)
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
