"""The physics settings table: each setting's cost beside the paper chain's, and how far it moves each score."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from woody_experiments import physics_settings
from woody_experiments.experiment import RunSpec, evaluate_run
from woody_sim.meshes import generate_fillet


def test_a_spawn_offset_moves_the_fillet_down_the_belt_and_its_frames_with_it():
    mesh = generate_fillet(0)
    spec = RunSpec(mesh=mesh.name, k=0.0, speed_fpm=100.0, side=False, lanes=1)
    base, later = evaluate_run(spec, mesh)[0], evaluate_run(replace(spec, spawn_offset_m=0.006), mesh)[0]
    assert base["status"] == later["status"] == "scored"
    assert later["line_phi"] != base["line_phi"]  # another phase of the camera's frames
    assert later["line_phi"] == pytest.approx(base["line_phi"], rel=0.5)


def test_the_reference_moves_nothing_and_a_coarser_step_is_cheaper_and_moves_the_scores(monkeypatch):
    monkeypatch.setattr(physics_settings, "SETTINGS",
                        {physics_settings.REFERENCE: {}, "240 Hz": {"dt": 1.0 / 240.0}})
    costs = iter([2.0, 1.0])  # the reference's wall s per sim-s, then the setting's
    figures = physics_settings.evaluate_settings([generate_fillet(0)], [0.0], [100.0], lambda config: next(costs))
    reference, spread, coarse = figures
    assert reference.changes["line_phi"] == (0.0, 0.0) and reference.speedup == 1.0
    assert math.isnan(spread.wall_per_sim_s) and spread.name == physics_settings.SPREAD
    assert coarse.speedup == pytest.approx(2.0)
    assert coarse.changes["nmdm"][0] > 0.0 and coarse.runs == 1
    table = physics_settings.markdown_table(figures)
    assert "| 240 Hz | 1.000 | 2.00× |" in table and table.count("\n") == 2 + len(figures)


def test_a_coarser_chain_carries_the_papers_hinges_in_series_and_bends_like_its_chain():
    from woody_sim.line_world import PhysicsConfig, calibrated_config

    assert PhysicsConfig(n_segments=40).hinge_scale == 1.0 and PhysicsConfig(n_segments=20).hinge_scale == 0.5
    mesh = generate_fillet(0)
    spec = RunSpec(mesh=mesh.name, k=100.0, speed_fpm=100.0, top=False)
    paper, coarse = (evaluate_run(spec, mesh, calibrated_config(n_segments=n))[1] for n in (40, 20))
    assert coarse["nmdm"] == pytest.approx(paper["nmdm"], rel=0.02)  # an unscaled 20-slice chain is stiffer
