"""line_sim's wall time by phase: accumulated per lap, summarised in one log line and read back."""

import time

import pytest

from woody_sim.loop_phases import SUMMARY_PREFIX, PhaseClock, parse_summary


def test_each_lap_charges_the_time_since_the_previous_one_to_its_phase():
    clock = PhaseClock()
    time.sleep(0.02)
    clock.lap("physics")
    time.sleep(0.01)
    clock.lap("publish")
    clock.lap("physics")
    assert clock.totals["physics"] == pytest.approx(0.02, abs=0.015)
    assert clock.totals["publish"] == pytest.approx(0.01, abs=0.015)
    assert clock.totals["physics"] > clock.totals["publish"]


def test_the_summary_line_reads_back_as_shares_of_the_wall_time():
    clock = PhaseClock()
    clock.totals = {"physics": 3.0, "render_wait": 1.0}
    line = clock.summary()
    assert line == f"{SUMMARY_PREFIX} physics 75.0 %, render_wait 25.0 %"
    log = f"[INFO] [line_sim]: stopped\n[INFO] [line_sim]: {line}\n"
    assert parse_summary(log) == {"physics": 75.0, "render_wait": 25.0}
    assert parse_summary("no such line") == {}
