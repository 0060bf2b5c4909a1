"""SplitLineWorld: fillets in the workers move bit for bit as alone in a world; load balance, removals, errors and
misuse."""

from __future__ import annotations

import os
import signal
import time

import numpy as np
import pytest

from woody_sim.line_geometry import LineGeometry
from woody_sim.line_world import LineWorld, PhysicsConfig, calibrated_config
from woody_sim.meshes import FilletMesh, load_mesh_set
from woody_sim.split_world import SplitLineWorld

GEOMETRY = LineGeometry(lanes=3, spawn_x=-0.3)
SPEED = 0.508
MASS = 20.0


@pytest.fixture(scope="module")
def meshes() -> list[FilletMesh]:
    return load_mesh_set("builtin")[0]


def alone(mesh: FilletMesh, k: float, lane: int, spawn_step: int, steps: int) -> np.ndarray:
    """Poses of one fillet, the only one in its world, after ``steps`` steps."""
    with LineWorld(GEOMETRY, calibrated_config()) as world:
        while world.steps < spawn_step:
            world.step()
        fid = world.spawn(mesh, k, lane, MASS, SPEED)
        while world.steps < steps:
            world.step()
        return world.segment_poses()[fid]


def test_each_fillet_moves_as_alone_in_a_world_whichever_process_simulates_it(meshes):
    """The first spawn goes to the worker, the second stays here (the worker has more fillets by then); the
    worker hears of its spawn late, and both tip over the roller exactly as a lone chain would (a shared world
    would differ in round-off by millimetres)."""
    steps = round(0.69 / calibrated_config().dt)
    with SplitLineWorld(GEOMETRY, calibrated_config()) as world:
        there = world.spawn(meshes[0], 0.0, 0, MASS, SPEED)
        for _ in range(5):
            world.step()
        here = world.spawn(meshes[1], 100.0, 2, MASS, SPEED)
        assert here in world._local.fillets and there in world._workers[0].models
        world.plan(steps * world.config.dt)
        while world.steps < steps:
            world.step()
        poses = world.segment_poses()
        assert world.model(there).total_mass == pytest.approx(MASS)
    assert np.array_equal(poses[there], alone(meshes[0], 0.0, 0, 0, steps))
    assert np.array_equal(poses[here], alone(meshes[1], 100.0, 2, 5, steps))
    assert poses[there][-1, 2] < -0.02 and poses[here][-1, 0] > 0.05  # both past the edge


def test_fillets_the_worker_removes_are_reported_after_the_next_poses(meshes):
    with SplitLineWorld(GEOMETRY, calibrated_config()) as world:
        ids = [world.spawn(meshes[0], 100.0, lane, MASS, SPEED) for lane in (0, 1)]
        while world.time < 2.5:
            world.step()
            if world.steps % 50 == 0:
                world.segment_poses()
        removed = world.take_removed()
        assert world.segment_poses() == {}
        removed += world.take_removed()
        assert sorted(removed) == ids and world.blown_up == []


def test_bad_spawns_are_refused_here_and_ids_stay_unique(meshes):
    with SplitLineWorld(GEOMETRY, calibrated_config()) as world:
        first, second = (world.spawn(meshes[0], 10.0, lane, MASS, SPEED) for lane in (0, 1))
        with pytest.raises(ValueError, match="already on the line"):
            world.spawn(meshes[0], 10.0, 2, MASS, SPEED, fillet_id=second)
        with pytest.raises(ValueError, match="lane"):
            world.spawn(meshes[0], 10.0, 3, MASS, SPEED)
        assert world.spawn(meshes[0], 10.0, 2, MASS, SPEED) == 2 and first == 0


def test_poses_before_the_planned_step_are_an_error(meshes):
    with SplitLineWorld(GEOMETRY, calibrated_config()) as world:
        world.plan(0.1)
        world.step()
        with pytest.raises(RuntimeError, match="sent on to"):
            world.segment_poses()


def test_a_dead_worker_is_an_error_not_a_hang(meshes):
    with SplitLineWorld(GEOMETRY, calibrated_config()) as world:
        world.spawn(meshes[0], 10.0, 0, MASS, SPEED)
        os.kill(world._workers[0].process.pid, signal.SIGKILL)
        world.step()
        with pytest.raises(RuntimeError, match="physics worker 0 process died"):
            world.segment_poses()


def test_a_world_that_simulates_the_whole_belt_cannot_be_split():
    with pytest.raises(ValueError, match="activation_margin"):
        SplitLineWorld(GEOMETRY, PhysicsConfig(activation_margin=None))


def test_the_worker_ends_when_its_parent_is_killed():
    """A line_sim killed with SIGKILL leaves no physics worker behind."""
    import subprocess
    import sys

    script = ("import sys, time\n"
              "from woody_sim.line_geometry import LineGeometry\n"
              "from woody_sim.line_world import calibrated_config\n"
              "from woody_sim.split_world import SplitLineWorld\n"
              "if __name__ == '__main__':\n"
              "    world = SplitLineWorld(LineGeometry(), calibrated_config())\n"
              "    print(world._workers[0].process.pid, flush=True)\n"
              "    time.sleep(60)\n")
    parent = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    worker = int(parent.stdout.readline())
    os.kill(parent.pid, signal.SIGKILL)
    parent.wait(timeout=10)
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline and os.path.exists(f"/proc/{worker}"):
        time.sleep(0.1)
    assert not os.path.exists(f"/proc/{worker}")


def test_a_released_mesh_key_is_never_given_to_another_mesh(meshes):
    """Placed meshes come and go on a messy line: a mesh registered after a release gets a key of its own, so the
    worker neither spawns the wrong mesh nor fails to release one."""
    from woody_sim.meshes import scaled

    placed = [scaled(meshes[0], s) for s in (0.9, 1.0, 1.1)]
    with SplitLineWorld(GEOMETRY, calibrated_config()) as world:
        world.model_for(placed[0])
        world.model_for(placed[1])
        world.release(placed[0])
        world.model_for(placed[2])
        world.release(placed[1])
        world.release(placed[2])
        world.plan(world.config.dt)
        world.step()
        assert world.segment_poses() == {}


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="two physics workers need two cores")
def test_each_spawn_goes_where_the_fewest_fillets_live_and_moves_as_alone(meshes):
    """Six lanes spawning together over this process and two workers: two fillets each, workers first; a removed
    fillet frees its world's place, and every chain moves as a lone one: to round-off, since two chains of one
    process share a pybullet world and its contact order (test_physics, a chain in a world that ran others)."""
    geometry = LineGeometry(lanes=6, spawn_x=-0.3)
    with SplitLineWorld(geometry, calibrated_config(), workers=2) as world:
        ids = [world.spawn(meshes[lane % 3], 100.0, lane, MASS, SPEED) for lane in range(6)]
        assert [len(w.models) for w in world._workers] == [2, 2] and len(world._local.fillets) == 2
        assert set(world._workers[0].models) == {ids[0], ids[3]} and set(world._local.fillets) == {ids[2], ids[5]}
        steps = round(0.42 / world.config.dt)  # tipping over the roller
        world.plan(steps * world.config.dt)
        while world.steps < steps:
            world.step()
        poses = world.segment_poses()
    with LineWorld(geometry, calibrated_config()) as lone:
        fid = lone.spawn(meshes[1], 100.0, 4, MASS, SPEED)
        while lone.steps < steps:
            lone.step()
        assert lone.is_dynamic(fid)
        assert np.abs(poses[ids[4]] - lone.segment_poses()[fid]).max() < 1e-4


def test_more_workers_than_cores_are_refused():
    with pytest.raises(ValueError, match="cores of this machine"):
        SplitLineWorld(GEOMETRY, calibrated_config(), workers=(os.cpu_count() or 1) + 1)


def run_to(world, steps: int) -> dict[int, np.ndarray]:
    """Step to ``steps`` as line_sim does (plan, step, poses) and return the poses there."""
    world.plan(steps * world.config.dt)
    while world.steps < steps:
        world.step()
    return world.segment_poses()


def wait_for_successors(world: SplitLineWorld) -> None:
    """Until every successor has started and taken its worker's place (a spawn checks; here, a busy wait)."""
    deadline = time.monotonic() + 30.0
    while world._successors and time.monotonic() < deadline:
        time.sleep(0.05)
        world._take_up_successors()
    assert not world._successors


def test_a_recycled_worker_hands_over_to_a_fresh_process_and_ends_once_its_fillets_are_gone(meshes):
    """With recycling, every spawn goes to a worker; at its first spawn (recycle_after 1) a successor starts, takes
    the next spawns once it has answered, joins the line's clock where it is, and the old process ends once its
    chain has left. Both chains, in the old process and the new, move as lone ones."""
    with SplitLineWorld(GEOMETRY, calibrated_config(), recycle_after=1) as world:
        first = world.spawn(meshes[1], 100.0, 1, MASS, SPEED)
        old_pid = world.worker_pids[0]
        run_to(world, 40)
        wait_for_successors(world)
        late = world.spawn(meshes[2], 0.0, 2, MASS, SPEED)
        assert world._workers[0].models.keys() == {late}
        assert world.workers_started == 3  # the successor took its one spawn too: its own successor is starting
        assert sorted(world.worker_pids) == sorted([old_pid, world._workers[0].process.pid])
        assert not world._local.fillets
        poses = run_to(world, 330)
        assert np.array_equal(poses[first], alone(meshes[1], 100.0, 1, 0, 330))
        assert np.array_equal(poses[late], alone(meshes[2], 0.0, 2, 40, 330))
        deadline = time.monotonic() + 30.0  # the chain leaves within 2 sim-s, and a process ends in under 1 s
        while (world._retiring or world._ending) and time.monotonic() < deadline:
            run_to(world, world.steps + 60)
            time.sleep(0.01)
        assert old_pid not in world.worker_pids and not world._retiring and not world._ending
        assert not os.path.exists(f"/proc/{old_pid}")


def test_a_successor_follows_a_belt_speed_change_asked_before_it_started(meshes):
    """A speed change planned for later reaches a worker started after it was asked for."""
    change = 60 * calibrated_config().dt
    with SplitLineWorld(GEOMETRY, calibrated_config(), recycle_after=1) as world:
        world.change_speed(0.66, change)
        world.spawn(meshes[0], 0.0, 0, MASS, SPEED)
        wait_for_successors(world)
        late = world.spawn(meshes[1], 0.0, 1, MASS, SPEED)
        poses = run_to(world, 120)
    with LineWorld(GEOMETRY, calibrated_config()) as lone:
        lone.change_speed(0.66, change)
        fid = lone.spawn(meshes[1], 0.0, 1, MASS, SPEED)
        while lone.steps < 120:
            lone.step()
        assert np.array_equal(poses[late], lone.segment_poses()[fid])
