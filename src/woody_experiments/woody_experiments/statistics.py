"""The statistics of the experiments: finite values, mean ± sd, the Φ rule's accuracy, ROC, best threshold, Wilson.

Normal (k = 0) fillets against severe (k = 100) ones under the grader's reject rule,
woody where Φ is strictly below the threshold (woody_vision.grading.is_woody_array;
positive = severe); every function drops non-finite values first.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from woody_vision.grading import is_woody_array

Z95 = 1.959963984540054
"""Two-sided 95 % standard normal quantile."""


def finite(values) -> np.ndarray:
    a = np.asarray([v for v in values], dtype=float)
    return a[np.isfinite(a)]


def mean_sd(values) -> tuple[float, float, int]:
    a = finite(values)
    if a.size == 0:
        return math.nan, math.nan, 0
    return float(a.mean()), float(a.std(ddof=1)) if a.size > 1 else 0.0, int(a.size)


def roc(normal: Sequence[float], severe: Sequence[float]) -> tuple[np.ndarray, np.ndarray, float]:
    """ROC of the reject rule over every cut t (positive = severe): (false-positive rates, true-positive rates,
    AUC)."""
    n, s = finite(normal), finite(severe)
    if n.size == 0 or s.size == 0:
        return np.array([0.0, 1.0]), np.array([0.0, 1.0]), math.nan
    thresholds = np.concatenate([[-np.inf], np.unique(np.concatenate([n, s])), [np.inf]])
    tpr = np.array([is_woody_array(s, t).mean() for t in thresholds] + [1.0])
    fpr = np.array([is_woody_array(n, t).mean() for t in thresholds] + [1.0])
    # AUC = P(Φ_normal > Φ_severe) + 0.5 P(tie)
    greater = (n[:, None] > s[None, :]).mean()
    ties = (n[:, None] == s[None, :]).mean()
    return fpr, tpr, float(greater + 0.5 * ties)


def accuracy(normal: Sequence[float], severe: Sequence[float], threshold: float) -> tuple[float, int, int]:
    """Fraction right under the reject rule at ``threshold``; returns (accuracy, right, total)."""
    n, s = finite(normal), finite(severe)
    right = int((~is_woody_array(n, threshold)).sum() + is_woody_array(s, threshold).sum())
    total = int(n.size + s.size)
    return (right / total if total else math.nan), right, total


def balanced_accuracy(normal, severe, threshold: float) -> float:
    n, s = finite(normal), finite(severe)
    if n.size == 0 or s.size == 0:
        return math.nan
    return 0.5 * ((~is_woody_array(n, threshold)).mean() + is_woody_array(s, threshold).mean())


def best_threshold(normal: Sequence[float], severe: Sequence[float]) -> tuple[float, float]:
    """Threshold maximising balanced accuracy (midpoint of the widest best gap); returns (threshold, bal. acc.)."""
    n, s = finite(normal), finite(severe)
    values = np.unique(np.concatenate([n, s]))
    candidates = np.concatenate([[values[0] - 1.0], (values[:-1] + values[1:]) / 2.0, [values[-1] + 1.0]])
    scores = np.array([balanced_accuracy(n, s, t) for t in candidates])
    best = scores.max()
    idx = np.flatnonzero(np.isclose(scores, best))
    # among equally good cuts take the middle of the best run: the most margin on both sides
    run = idx[idx - idx[0] == np.arange(idx.size)]
    lo, hi = candidates[run[0]], candidates[run[-1]]
    if run.size > 1:
        t = 0.5 * (lo + hi)
    else:
        t = float(candidates[run[0]])
    return float(t), float(best)


def wilson_interval(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion; (nan, nan) for n = 0."""
    if n <= 0:
        return math.nan, math.nan
    if not 0 <= successes <= n:
        raise ValueError(f"successes must be in 0..{n}, got {successes}")
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z / denom * math.sqrt(p * (1.0 - p) / n + z * z / (4 * n * n))
    return max(0.0, centre - half), min(1.0, centre + half)


def share_text(successes: int, n: int) -> str:
    """A proportion with its count and 95 % Wilson interval, "91.7 % (22/24; 74–98 %)"; "—" for n = 0."""
    if not n:
        return "—"
    lo, hi = wilson_interval(successes, n)
    return f"{successes / n * 100:.1f} % ({successes}/{n}; {lo * 100:.0f}–{hi * 100:.0f} %)"
