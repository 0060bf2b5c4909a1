"""A belt speed change during a run: riding fillets, chains and the physics worker all follow it."""

from __future__ import annotations

import numpy as np
import pytest

from woody_sim.line_geometry import LineGeometry
from woody_sim.line_world import LineWorld, calibrated_config
from woody_sim.meshes import FilletMesh, load_mesh_set
from woody_sim.split_world import SplitLineWorld

GEOMETRY = LineGeometry(lanes=3, spawn_x=-0.6)
OLD, NEW = 0.508, 0.660  # 100 and 130 FPM
MASS = 20.0


@pytest.fixture(scope="module")
def mesh() -> FilletMesh:
    return load_mesh_set("builtin")[0][0]


def step_to(world, t: float) -> None:
    while world.time < t - 1e-9:
        world.step()


def test_a_riding_fillet_moves_on_at_the_new_speed(mesh):
    with LineWorld(GEOMETRY, calibrated_config()) as world:
        fid = world.spawn(mesh, 0.0, 1, MASS, OLD, lateral_offset=0.01)
        start = world.segment_poses()[fid][:, :3].copy()
        world.change_speed(NEW, at_time=0.1)
        step_to(world, 0.3)
        assert not world.is_dynamic(fid)
        moved = world.segment_poses()[fid][:, :3] - start
        change = np.ceil(0.1 / world.config.dt - 1e-9) * world.config.dt  # applied at the first step at or after
        assert moved[:, 0] == pytest.approx(OLD * change + NEW * (world.time - change), abs=1e-9)
        assert np.allclose(moved[:, 1:], 0.0) and start[:, 1].mean() == pytest.approx(0.01, abs=0.01)
        assert np.allclose(world.segment_velocities(fid)[:, 0], NEW)
        assert world.fillets[fid].speed_mps == OLD  # the ground truth keeps the speed at spawn
        with pytest.raises(ValueError, match="at or after now"):
            world.change_speed(OLD, at_time=0.1)


def test_a_chain_reaching_the_roller_after_the_change_is_driven_at_the_new_speed(mesh):
    with LineWorld(LineGeometry(lanes=3, spawn_x=-0.15), calibrated_config()) as world:
        fid = world.spawn(mesh, 100.0, 1, MASS, OLD)
        world.change_speed(NEW)
        while not world.is_dynamic(fid):
            world.step()
        for _ in range(10):
            world.step()
        assert world.segment_velocities(fid)[:3, 0] == pytest.approx(NEW, abs=0.01)  # the trailing end on the belt


def test_the_worker_applies_the_change_at_the_same_step_even_for_fillets_it_hears_of_late(mesh):
    """The second spawn goes to the worker, which may place it after the change: it must ride as the plain world's."""
    spawn_steps, steps = (0, 40, 100), 200
    with LineWorld(GEOMETRY, calibrated_config()) as plain, SplitLineWorld(GEOMETRY, calibrated_config()) as split:
        for world in (plain, split):
            world.change_speed(NEW, at_time=0.1)
        for spawn_step in spawn_steps:
            for world in (plain, split):
                step_to(world, spawn_step * world.config.dt)
                world.spawn(mesh, 0.0, 1, MASS, NEW if world.time >= 0.1 else OLD)
            split.plan(150 * split.config.dt)  # the worker runs ahead of the spawns that follow
        split.plan(steps * split.config.dt)
        for world in (plain, split):
            step_to(world, steps * world.config.dt)
        expected, got = plain.segment_poses(), split.segment_poses()
        assert sorted(got) == sorted(expected) == [0, 1, 2]
        for fid in expected:
            assert np.array_equal(got[fid], expected[fid])
        with pytest.raises(ValueError, match="stepped past"):
            split.change_speed(OLD, at_time=0.05)
