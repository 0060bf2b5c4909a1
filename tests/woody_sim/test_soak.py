"""The shift soak: a long messy line through one physics world, its resident memory sampled as fillets leave."""

from __future__ import annotations

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


def test_woody_soak_shift_prints_memory_and_growth():
    result = subprocess.run([entry_point("woody"), "soak", "--shift", "6", "--lanes", "3"], capture_output=True,
                            text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "6 fillets gone:" in result.stdout and "MB per 1,000 fillets" in result.stdout
