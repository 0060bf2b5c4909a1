"""woody_experiments.paper_targets: the paper's tables are complete and consistent with the bands."""

from __future__ import annotations

from woody_common.line import CLASS_K, PAPER_SPEEDS_FPM
from woody_experiments import paper_targets as t


def test_tables_cover_the_papers_speeds_and_classes():
    assert set(t.PAPER_SIDE) == set(t.PAPER_TOP) == set(PAPER_SPEEDS_FPM)
    for speed in PAPER_SPEEDS_FPM:
        assert set(CLASS_K) <= set(t.PAPER_SIDE[speed]) and set(CLASS_K) <= set(t.PAPER_TOP[speed])
    assert t.PAPER_NMDM == {(s, k): row[0] for s, table in t.PAPER_SIDE.items() for k, row in table.items()}
    assert sorted(t.PAPER_LANES) == [0, 1, 2]


def test_the_papers_figures_meet_its_own_targets():
    normal, severe = (t.PAPER_SIDE[100.0][k][0] for k in CLASS_K)
    assert t.DELTA_NMDM_RANGE[0] <= severe - normal <= t.DELTA_NMDM_RANGE[1]
    assert abs((severe - normal) - t.PAPER_DELTA_NMDM) < 0.01
    assert t.NMDM_NORMAL_RANGE[0] <= normal <= t.NMDM_NORMAL_RANGE[1]
    assert t.PAPER_SIDE[130.0][0.0][0] - normal >= t.SPEED_GAIN_MIN
    phi_normal, phi_severe = (t.PAPER_TOP[100.0][k][0] for k in CLASS_K)
    assert phi_normal / phi_severe >= t.PHI_RATIO_MIN
    assert 1 - t.PAPER_TOP[130.0][0.0][0] / phi_normal >= t.PHI_SPEED_DROP_MIN
    for lane, (n_mean, _, s_mean, _, delta) in t.PAPER_LANES.items():
        assert abs((n_mean - s_mean) - delta) < 0.02, lane  # the published figures are rounded
    assert 0.5 < t.ACCURACY_MIN <= 1.0 and t.PHI_SD_FACTOR > 1.0
