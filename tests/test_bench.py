"""The benchmark's same-run yardstick: a reference time, and figures divided by it the right way round."""

from __future__ import annotations

import pytest

from woody_tools.benchmarks.command import reference_ms, with_reference


def test_reference_workload_takes_measurable_time():
    assert 0.1 < reference_ms(repeats=3) < 5000.0


def test_times_are_divided_by_the_reference_and_rates_multiplied():
    out = with_reference({"render_top_ms": 4.0, "rtf": 1.5, "sweep_evals_per_min": 300.0, "frames": 300}, 2.0)
    assert out["render_top_ms_ref"] == pytest.approx(2.0)  # two reference workloads
    assert out["rtf_ref"] == pytest.approx(0.003)  # sim seconds per reference workload
    assert out["sweep_evals_per_min_ref"] == pytest.approx(0.6)
    assert "frames_ref" not in out and list(out)[:2] == ["render_top_ms", "render_top_ms_ref"]
