"""The shift soak: a long messy line through one physics world, its resident memory sampled as fillets leave."""

from __future__ import annotations

import os
import subprocess

import pytest

from woody_sim import line_world
from woody_sim.line_world import LineWorld, calibrated_config
from woody_sim.meshes import load_mesh_set
from woody_sim.soak import growth_mb_per_1000, shift
from woody_tools.processes import entry_point


def test_a_shift_of_placed_fillets_runs_through_one_world_and_samples_its_memory():
    meshes, _ = load_mesh_set("builtin")
    result = shift(meshes, 9, 20.0, lanes=3, samples=3, config=calibrated_config())
    assert result.fillets == 9 and result.blowups == 0 and result.sim_s > 0.0
    assert [gone for gone, _ in result.rss_mb] == [3, 6, 9] and all(rss > 50.0 for _, rss in result.rss_mb)


def test_growth_is_the_slope_over_the_second_half_of_the_samples():
    samples = [(100, 300.0), (200, 250.0), (300, 251.0), (400, 252.0)]  # start-up first, then 1 MB per 100
    assert growth_mb_per_1000(samples) == pytest.approx(10.0)


def test_a_recycled_world_gives_its_heap_back_when_it_closes(monkeypatch):
    trims = []
    monkeypatch.setattr(line_world, "CHAINS_PER_PHYSICS", 2)
    monkeypatch.setattr(line_world, "return_freed_memory", lambda: trims.append(1))
    meshes, _ = load_mesh_set("builtin")
    with LineWorld() as world:
        for lane in range(3):  # the third chain goes to a second world; the first closes once both of its are gone
            world.spawn(meshes[0], 0.0, lane, 20.0, 0.5)
        while world.fillets:
            world.step()
    assert trims


def test_released_placed_meshes_are_collected_every_so_many(monkeypatch):
    """A placed mesh is cyclic garbage once released (a trimesh and its visuals refer to each other): the world runs
    the full collection every RELEASES_PER_COLLECT releases, so a shift's processes do not pile them up."""
    from woody_sim.meshes import scaled

    collections = []
    monkeypatch.setattr(line_world, "RELEASES_PER_COLLECT", 3)
    monkeypatch.setattr(line_world.gc, "collect", lambda: collections.append(1))
    meshes, _ = load_mesh_set("builtin")
    with LineWorld() as world:
        for size in (0.9, 0.95, 1.0, 1.05, 1.1, 1.15, 1.2):
            world.release(scaled(meshes[0], size))
    assert len(collections) == 2


def test_a_shift_through_recycled_physics_workers_samples_every_process():
    meshes, _ = load_mesh_set("builtin")
    result = shift(meshes, 6, 20.0, lanes=3, samples=2, config=calibrated_config(), workers=1, recycle_after=2)
    assert result.fillets == 6 and result.blowups == 0 and result.workers_started >= 2
    assert [gone for gone, _ in result.worker_rss_mb] == [3, 6] and all(rss > 50.0 for _, rss in result.worker_rss_mb)


def test_woody_soak_shift_prints_memory_and_growth():
    result = subprocess.run([entry_point("woody"), "soak", "--shift", "6", "--lanes", "3", "--physics-workers", "1",
                             "--recycle-after", "3"], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "6 fillets gone:" in result.stdout and "largest physics worker" in result.stdout
    assert "MB per 1,000 fillets" in result.stdout and "physics workers: " in result.stdout


def test_woody_soak_shift_refuses_recycling_without_workers_in_one_line():
    result = subprocess.run([entry_point("woody"), "soak", "--shift", "6", "--recycle-after", "3"],
                            capture_output=True, text=True, timeout=120)
    lines = [line for line in result.stderr.splitlines() if not line.startswith("pybullet build time")]
    assert result.returncode == 2 and lines == [
        f"woody soak: --shift must be 1..1000000, --lanes 1..6, --physics-workers 0..{min(os.cpu_count() or 1, 64)} "
        "(the cores) and --recycle-after >= 0 (above 0 with --physics-workers >= 1)"]
