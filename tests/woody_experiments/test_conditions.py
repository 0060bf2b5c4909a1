"""woody_experiments.conditions: the sweep's named lines and each run's seeded placement."""

from __future__ import annotations

import pytest

from woody_experiments.conditions import SWEEP_CONDITIONS, run_placement, sweep_condition
from woody_sim.line_conditions import MAX_YAW_DEG, line_preset


def test_each_disturbance_alone_takes_the_messy_preset_numbers():
    messy = line_preset("messy")
    assert SWEEP_CONDITIONS["turned"].yaw_sd_deg == messy.yaw_sd_deg and SWEEP_CONDITIONS["turned"].scale_max == 1.0
    assert (SWEEP_CONDITIONS["size"].scale_min, SWEEP_CONDITIONS["size"].scale_max) == (messy.scale_min,
                                                                                          messy.scale_max)
    assert SWEEP_CONDITIONS["blunt"].blunt_fraction == 1.0 and SWEEP_CONDITIONS["messy"] == messy


def test_the_wide_line_spreads_turns_over_every_turn_the_line_allows():
    turns = [abs(run_placement(f"generated-{i}", "wide", 100.0).yaw_deg) for i in range(200)]
    blunt = sum(run_placement(f"generated-{i}", "wide", 100.0).blunt_first for i in range(200))
    assert max(turns) <= MAX_YAW_DEG and sum(t > 25.0 for t in turns) > 50  # the messy line: about 1 in 10
    assert 70 < blunt < 130


def test_a_runs_placement_is_seeded_by_mesh_condition_and_speed():
    placement = run_placement("seed0000", "messy", 130.0)
    assert placement == run_placement("seed0000", "messy", 130.0)
    assert placement != run_placement("seed0001", "messy", 130.0)
    assert placement != run_placement("seed0000", "messy", 100.0)
    assert abs(placement.lateral_offset_m) <= line_preset("messy").lateral_max_m
    assert run_placement("seed0000", "tidy", 130.0).keeps_mesh
    assert run_placement("seed0000", "blunt", 100.0).blunt_first


def test_an_unknown_condition_is_one_line():
    with pytest.raises(ValueError, match="unknown condition 'wet'; known: tidy"):
        sweep_condition("wet")
