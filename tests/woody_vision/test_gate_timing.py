"""woody_vision.gate_timing: when a lane's diverter opens for a fillet."""

from __future__ import annotations

import math

import pytest

from woody_vision.gate_timing import GateTiming


def test_the_gate_opens_half_its_open_time_before_the_fillet_centre_arrives():
    timing = GateTiming(line_speed_mps=0.5, gate_distances_m=[0.6, 0.8], open_duration_s=0.2)
    assert timing.actuation_time(0, 10.0) == pytest.approx(10.0 + 1.2 - 0.1)
    assert timing.actuation_time(1, 10.0) == pytest.approx(10.0 + 1.6 - 0.1)


def test_a_measured_fillet_speed_sets_the_travel_time_when_plausible():
    timing = GateTiming(line_speed_mps=0.5, gate_distances_m=[0.6], open_duration_s=0.2)
    assert timing.actuation_time(0, 0.0, 0.6) == pytest.approx(1.0 - 0.1)  # the line sped up: earlier
    for implausible in (math.nan, 0.1, 5.0, -0.5):
        assert timing.actuation_time(0, 0.0, implausible) == pytest.approx(1.2 - 0.1)


@pytest.mark.parametrize("kwargs", [dict(line_speed_mps=0.0, gate_distances_m=[0.6]),
                                    dict(line_speed_mps=0.5, gate_distances_m=[]),
                                    dict(line_speed_mps=0.5, gate_distances_m=[0.6, -1.0]),
                                    dict(line_speed_mps=0.5, gate_distances_m=[0.6], open_duration_s=0.0)])
def test_bad_timings_are_refused(kwargs):
    with pytest.raises(ValueError):
        GateTiming(**kwargs)


def test_a_lane_without_a_diverter_is_refused():
    with pytest.raises(ValueError, match="lane 2 has no diverter"):
        GateTiming(line_speed_mps=0.5, gate_distances_m=[0.6, 0.6]).actuation_time(2, 0.0)
