"""woody_experiments.statistics: the reject rule's accuracy, ROC and best cut, mean ± sd, Wilson intervals."""

from __future__ import annotations

import math

import numpy as np
import pytest

from woody_experiments.statistics import (
    accuracy,
    balanced_accuracy,
    best_threshold,
    finite,
    mean_sd,
    roc,
    share_text,
    wilson_interval,
)


def test_accuracy_uses_the_graders_rule_strictly_below():
    assert accuracy([10.0], [9.99], 10.0) == (1.0, 2, 2)  # a normal fillet exactly at the cut passes
    assert accuracy([9.0, 12.0], [8.0, 11.0], 10.0) == (0.5, 2, 4)
    assert accuracy([math.nan], [math.nan], 10.0)[2] == 0  # non-finite values are dropped
    assert balanced_accuracy([12.0, 12.0, 9.0], [8.0], 10.0) == pytest.approx(0.5 * (2 / 3 + 1))


def test_roc_auc_and_best_threshold_separate_the_classes():
    normal, severe = [12.0, 13.0, 14.0], [5.0, 6.0, 7.0]
    fpr, tpr, auc = roc(normal, severe)
    assert auc == 1.0 and fpr[0] == tpr[0] == 0.0 and fpr[-1] == tpr[-1] == 1.0
    threshold, bacc = best_threshold(normal, severe)
    assert 7.0 < threshold < 12.0 and bacc == 1.0
    assert accuracy(normal, severe, threshold)[0] == 1.0
    assert roc([5.0], [5.0])[2] == 0.5  # a tie counts half
    assert math.isnan(roc([], [1.0])[2])


def test_mean_sd_finite_and_wilson():
    assert mean_sd([1.0, 3.0, math.nan]) == (2.0, pytest.approx(math.sqrt(2.0)), 2)
    assert mean_sd([4.0]) == (4.0, 0.0, 1)
    assert np.isnan(mean_sd([])[0])
    assert finite([1.0, math.inf, math.nan]).tolist() == [1.0]
    low, high = wilson_interval(8, 10)
    assert 0.44 < low < 0.8 < high < 0.97
    assert all(math.isnan(v) for v in wilson_interval(0, 0))
    assert share_text(8, 10) == "80.0 % (8/10; 49–94 %)" and share_text(0, 0) == "—"
