"""Physics on two cores: every other fillet is simulated in a worker process.

line_sim is bound by its physics on one core while the second core mostly idles (its renderer needs a
fraction of it). Fillets never touch one another (belt and roller are static), so a fillet moves the same
in whichever pybullet world it is: :class:`SplitLineWorld` hands every other spawn to a second
:class:`~woody_sim.line_world.LineWorld` in a worker process. The lanes of a line spawn together, so with
3 lanes the two worlds take 2 and 1 fillets of each spawn in turn.

The worker steps on its own between pose requests: :meth:`SplitLineWorld.plan` tells it the sim time of
the next one, both worlds step at once until then, and :meth:`SplitLineWorld.segment_poses` at that step
waits for the worker. Spawns reach the worker a few steps late and are placed where the belt has carried
them since (exact: a fillet moves analytically until it nears the roller). Fillets the worker removes are
reported with its poses, so :meth:`SplitLineWorld.take_removed` names them after the next pose request.
A belt speed change is sent to both worlds before the worker can have passed its step, so both apply it at
the same step.
"""

from __future__ import annotations

import multiprocessing.connection as mpc
import traceback
from typing import Any

import numpy as np

from woody_sim.child_process import ChildProcess, parent_messages
from woody_sim.fillet_model import FilletModel
from woody_sim.frame_schedule import DUE_SLACK
from woody_sim.line_geometry import LineGeometry
from woody_sim.line_world import LineWorld, PhysicsConfig, check_fillet_id, check_lateral_offset, check_spawn
from woody_sim.meshes import FilletMesh


class SplitLineWorld:
    """The part of :class:`~woody_sim.line_world.LineWorld`'s interface line_sim uses, over two worlds in two
    processes."""

    def __init__(self, geometry: LineGeometry, config: PhysicsConfig, start_method: str = "spawn",
                 timeout: float = 30.0) -> None:
        if config.activation_margin is None:
            raise ValueError("SplitLineWorld needs fillets that start on the belt (activation_margin set)")
        self.geometry, self.config = geometry, config
        self._local = LineWorld(geometry, config)
        self._worker = ChildProcess(_serve, (geometry, config), "physics worker", start_method, timeout)
        self._mesh_keys: dict[FilletMesh, int] = {}
        self._remote_models: dict[int, FilletModel] = {}
        self._remote_poses: dict[int, np.ndarray] = {}
        self._asked = self._reached = 0  # the step the worker was last sent to, and the step it answered from
        self._removed: list[int] = []
        self._blown: list[int] = []
        self._next_id = self._spawned = self._next_key = 0

    @property
    def time(self) -> float:
        return self._local.time

    @property
    def steps(self) -> int:
        return self._local.steps

    @property
    def blown_up(self) -> list[int]:
        """Ids of fillets removed because their chain blew up, in both worlds."""
        return self._local.blown_up + self._blown

    def model_for(self, mesh: FilletMesh) -> FilletModel:
        """The chain geometry for a mesh; the worker builds its own copy meanwhile."""
        self._mesh_key(mesh)
        return self._local.model_for(mesh)

    def _mesh_key(self, mesh: FilletMesh) -> int:
        """A mesh is sent to the worker once and named by its key afterwards."""
        key = self._mesh_keys.get(mesh)
        if key is None:
            key = self._mesh_keys[mesh] = self._next_key  # never a released mesh's key: the worker forgot it
            self._next_key += 1
            self._worker.send(("mesh", key, mesh))
        return key

    def release(self, mesh: FilletMesh) -> None:
        """As :meth:`LineWorld.release <woody_sim.line_world.LineWorld.release>`, in both worlds."""
        self._local.release(mesh)
        key = self._mesh_keys.pop(mesh, None)
        if key is not None:
            self._worker.send(("release", key))

    def change_speed(self, speed_mps: float, at_time: float | None = None) -> None:
        """As :meth:`LineWorld.change_speed <woody_sim.line_world.LineWorld.change_speed>`; ``at_time`` may
        not come before a step the worker has been sent on to (call it before :meth:`plan` passes it)."""
        at = self.time if at_time is None else float(at_time)
        if at < self._asked * self.config.dt - 1e-9:
            raise ValueError(f"the physics worker may have stepped past {at} s already (up to "
                             f"{self._asked * self.config.dt} s): change the belt speed earlier")
        self._local.change_speed(speed_mps, at)
        self._worker.send(("speed", float(speed_mps), at))

    def spawn(self, mesh: FilletMesh, k: float, lane: int, mass: float, speed_mps: float,
              fillet_id: int | None = None, lateral_offset: float = 0.0) -> int:
        """As :meth:`LineWorld.spawn <woody_sim.line_world.LineWorld.spawn>`; every other fillet goes to the
        worker."""
        k, lane, mass, speed = check_spawn(self.geometry, k, lane, mass, speed_mps)
        lateral_offset = check_lateral_offset(lateral_offset)
        live = self._remote_models.keys() | self._local.fillets.keys()
        fillet_id = check_fillet_id(self._next_id if fillet_id is None else fillet_id, live)
        if self._spawned % 2:
            self._send_to(self.steps)  # the worker must have reached the spawn's step when it reads it
            self._worker.send(("spawn", self.steps, self._mesh_key(mesh), k, lane, mass, speed, fillet_id,
                               lateral_offset))
            self._remote_models[fillet_id] = self._local.model_for(mesh).with_mass(mass)
        else:
            self._local.spawn(mesh, k, lane, mass, speed, fillet_id, lateral_offset=lateral_offset)
        self._spawned += 1
        self._next_id = max(self._next_id, fillet_id + 1)
        return fillet_id

    def model(self, fillet_id: int) -> FilletModel:
        remote = self._remote_models.get(fillet_id)
        return remote if remote is not None else self._local.model(fillet_id)

    def step(self) -> float:
        """Step this process's world (the worker steps on its own towards the planned step)."""
        return self._local.step()

    def plan(self, until: float) -> None:
        """The next :meth:`segment_poses` comes at the first step at or after sim time ``until``: start the
        worker on the steps up to it."""
        dt = self.config.dt
        step = max(self.steps, int(until / dt) - 1)
        while step * dt + DUE_SLACK < until:  # the test FrameSchedule uses for a camera being due
            step += 1
        self._send_to(step)

    def _send_to(self, step: int) -> None:
        if step > self._asked:
            self._worker.send(("advance", step))
            self._asked = step

    def segment_poses(self) -> dict[int, np.ndarray]:
        """Every live fillet's (N, 7) segment poses now; waits for the worker to reach this step."""
        if self._asked > self.steps:
            raise RuntimeError(f"poses asked at step {self.steps}, but the worker was sent on to {self._asked}")
        self._send_to(self.steps)
        while self._reached < self.steps:
            self._take_answer()
        poses = self._local.segment_poses()
        poses.update(self._remote_poses)
        return poses

    def _take_answer(self) -> None:
        answer = self._worker.recv()
        if answer[0] != "at":
            raise RuntimeError(f"physics worker failed:\n{answer[1]}")
        _, self._reached, removed, blown, self._remote_poses = answer
        for fillet_id in removed:
            del self._remote_models[fillet_id]
        self._removed += removed
        self._blown += blown

    def take_removed(self) -> list[int]:
        """Ids removed since the last call; the worker's as of the last :meth:`segment_poses`."""
        removed, self._removed = self._local.take_removed() + self._removed, []
        return removed

    def close(self) -> None:
        self._worker.close()
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
        _, key, mesh = msg
        meshes[key] = mesh
        world.model_for(mesh)
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
