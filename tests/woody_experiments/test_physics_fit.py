"""woody_experiments.physics_fit: table means, the objective against the paper's side table, the grid search."""

from __future__ import annotations

import math

import pytest

from woody_experiments import physics_fit
from woody_experiments.paper_targets import DELTA_NMDM_RANGE, PAPER_NMDM, PAPER_SIDE


def rows_at(nmdm: dict) -> list[dict]:
    """Two meshes' side-view rows per (FPM, k) averaging to ``nmdm``; a row without NMDM is ignored."""
    rows = [{"speed_fpm": fpm, "k": k, "nmdm": value + d, "mdm": 50.0 + d} for (fpm, k), value in nmdm.items()
            for d in (-0.01, 0.01)]
    return rows + [{"speed_fpm": 100.0, "k": 0.0, "nmdm": math.nan, "mdm": math.nan}]


def test_table_means_average_over_meshes():
    means = physics_fit.table_means(rows_at(PAPER_NMDM))
    assert set(means) == set(PAPER_NMDM)
    assert means[(100.0, 0.0)] == pytest.approx((PAPER_SIDE[100.0][0.0][0], 50.0))


def test_the_papers_own_table_scores_zero_and_missing_cells_infinity():
    means = physics_fit.table_means(rows_at(PAPER_NMDM))
    assert DELTA_NMDM_RANGE[0] <= physics_fit.relations(means)["delta_nmdm_100fpm"] <= DELTA_NMDM_RANGE[1]
    assert physics_fit.objective(means) == pytest.approx(0.0, abs=1e-9)
    del means[(130.0, 400.0)]
    assert physics_fit.objective(means) == math.inf


def test_a_flat_table_pays_for_the_missing_stiffness_and_speed_effects():
    flat = {key: 0.7 for key in PAPER_NMDM}
    means = physics_fit.table_means(rows_at(flat))
    relations = physics_fit.relations(means)
    assert relations["delta_nmdm_100fpm"] == pytest.approx(0.0) and relations["nmdm_k0_speed_gain"] == pytest.approx(0)
    assert physics_fit.objective(means) > DELTA_NMDM_RANGE[0]


def test_search_picks_the_point_closest_to_the_paper():
    points = physics_fit.grid([10.0, 20.0], [0.1], [0.8])
    assert [(p.mass, p.damping, p.friction_static) for p in points] == [(10.0, 0.1, 0.8), (20.0, 0.1, 0.8)]
    assert points[0].friction_dynamic == pytest.approx(0.6)
    reported = []

    def evaluate(point):
        return rows_at(PAPER_NMDM if point.mass == 20.0 else {key: 0.7 for key in PAPER_NMDM})

    best, log = physics_fit.search(points, evaluate, lambda point, entry, score: reported.append(point))
    assert best == points[1] and reported == points
    assert [entry["mass"] for entry in log] == [10.0, 20.0] and log[1]["objective"] < log[0]["objective"]
    assert "100fpm_k0" in log[1]["table"]
