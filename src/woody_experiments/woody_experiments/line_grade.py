"""Fitting the line's grade: the reject cut and the severe cut on ``line_phi``, from experiment rows.

Classes by hinge stiffness k (N m/rad): normal k = 0, moderate 0 < k < 40,
severe k >= 40. The split is where the line score separates: at 100 FPM the
k = 10 and 20 fillets score between the normal and the k >= 40 ones, while k
40 and 100 overlap each other. The reject cut separates normal (k = 0) from
severe k = 100 fillets, the paper's two classes, with a margin to both; the
three-class grade refines that decision (woody_vision.grading.GradingRules),
so the moderate fillets it passes grade normal: the reject cut lies inside the
moderate class's scores, and the three-class figures say so.

Each cut is fitted between an upper (more compliant) and a lower class: per
class a least-squares fit of ln(score) on the measured conditions
(woody_vision.grading.covariates: speed, blunt end first, turn, body
length), and the cut runs between the two
lines, nearer the class with the smaller residual spread (each class's
residual sd weighs the other's line), so both classes keep the same margin
in units of their own spread. A row enters with what the grader measures
(``speed_mps``, ``leading_end``, ``turn_deg``, ``length_m``), never with the
simulator's settings.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from woody_common.line import NORMAL_K, SEVERE_K
from woody_experiments.statistics import roc
from woody_vision.grading import (
    GRADE_MODERATE,
    GRADE_NORMAL,
    GRADE_SEVERE,
    LABEL_NORMAL,
    LABEL_UNSCORED,
    Cut,
    FilletConditions,
    FittedRange,
    GradingRules,
    covariates,
    fitted_range_of,
)
from woody_vision.shape_score import LEADING_BLUNT

SEVERE_GRADE_MIN_K = 40.0
"""Stiffness from which a fillet grades severe; below it (and above 0) moderate."""
GRADES = (GRADE_NORMAL, GRADE_MODERATE, GRADE_SEVERE)


def true_grade(k: float) -> str:
    """The grade a fillet of stiffness ``k`` should get."""
    if k <= NORMAL_K:
        return GRADE_NORMAL
    return GRADE_SEVERE if k >= SEVERE_GRADE_MIN_K else GRADE_MODERATE


def conditions_of(row: dict) -> FilletConditions:
    """What the grader measured of a row's fillet."""
    return FilletConditions(float(row["speed_mps"]), row.get("leading_end") == LEADING_BLUNT,
                            float(row.get("turn_deg", math.nan)), float(row.get("length_m", math.nan)))


def _design(rows: Sequence[dict]) -> np.ndarray:
    return np.array([[1.0, *covariates(conditions_of(r))] for r in rows])


def _class_line(rows: Sequence[dict]) -> tuple[np.ndarray, float]:
    """Least-squares coefficients of ln(line_phi) on the design, and the residual sd. A score of 0 (a line read
    back to the axis, shape_score.extrapolate_at) has no logarithm and lies below every cut: it is left out."""
    rows = [r for r in rows if r["line_phi"] > 0.0]
    x, y = _design(rows), np.log([r["line_phi"] for r in rows])
    coef = np.linalg.lstsq(x, y, rcond=None)[0]
    dof = max(1, len(rows) - x.shape[1])
    return coef, max(float(np.sqrt(np.sum((y - x @ coef) ** 2) / dof)), 1e-6)


def fit_cut(upper: Sequence[dict], lower: Sequence[dict]) -> Cut:
    """The cut between a more compliant (upper) and a stiffer (lower) class of scored rows."""
    if min(len(upper), len(lower)) < 4:
        raise ValueError(f"a cut needs at least 4 scored rows per class, got {len(upper)} and {len(lower)}")
    (up, up_sd), (low, low_sd) = _class_line(upper), _class_line(lower)
    coef = (up * low_sd + low * up_sd) / (up_sd + low_sd)
    return Cut(math.exp(coef[0]), *(float(c) for c in coef[1:]))


def scored(rows: Sequence[dict]) -> list[dict]:
    """Rows whose line score was measured."""
    return [r for r in rows if r.get("status") == "scored" and math.isfinite(r.get("line_phi", math.nan))
            and math.isfinite(r.get("speed_mps", math.nan))]


def fitted_range(rows: Sequence[dict]) -> FittedRange:
    """The measured conditions of the scored rows the cuts are fitted on (:func:`fit_rules`)."""
    return fitted_range_of([conditions_of(r) for r in scored(rows)])


def fit_rules(rows: Sequence[dict]) -> GradingRules:
    """The reject cut (k = 0 vs k = 100, also the grade's normal/moderate boundary) and the grade's
    moderate/severe cut, from scored rows of several k."""
    rows = scored(rows)
    by_grade = {g: [r for r in rows if true_grade(r["k"]) == g] for g in GRADES}
    reject = fit_cut(by_grade[GRADE_NORMAL], [r for r in rows if r["k"] == SEVERE_K])
    severe = fit_cut(by_grade[GRADE_MODERATE], by_grade[GRADE_SEVERE])
    return GradingRules(reject, severe)


@dataclass(frozen=True)
class GradedRun:
    """One run as one vote under the line's rules: the median over its scored lanes."""

    mesh: str
    k: float
    speed_fpm: float
    condition: str
    score: float
    """Median ``line_phi`` over the scored lanes."""
    margin: float
    """ln(score / reject cut): negative is woody."""
    label: str
    """'normal', 'woody' or 'unscored' (measured outside the fitted range)."""
    grade: str


def graded_runs(rows: Sequence[dict], rules: GradingRules, fitted: FittedRange | None = None) -> list[GradedRun]:
    """Every run with a scored lane, graded on its median line score and median measured conditions; a run
    measured outside ``fitted`` is unscored, as the grader leaves such a fillet (the gate diverts it)."""
    groups: dict[tuple, list[dict]] = {}
    for r in scored(rows):
        groups.setdefault((r["mesh"], r["k"], r["speed_fpm"], r.get("condition") or "tidy"), []).append(r)
    out = []
    for (mesh, k, speed, condition), lanes in sorted(groups.items(), key=lambda kv: str(kv[0])):
        score = float(np.median([r["line_phi"] for r in lanes]))
        each = [conditions_of(r) for r in lanes]
        measured = FilletConditions(float(np.median([c.speed_mps for c in each])),
                                    sum(c.blunt_first for c in each) * 2 > len(each),
                                    float(np.median([c.turn_deg for c in each])),
                                    float(np.median([c.length_m for c in each])))
        decision = rules.classify(score, measured)
        unscored = fitted is not None and fitted.outside(measured)
        out.append(GradedRun(mesh, k, speed, condition, score, math.log(score / decision.threshold),
                             LABEL_UNSCORED if unscored else decision.label, "" if unscored else decision.grade or ""))
    return out


@dataclass(frozen=True)
class GradeSummary:
    """The line's figures on a set of runs: the reject decision on k = 0 vs 100, and the three-class grade."""

    normal_right: int
    normal_total: int
    severe_right: int
    severe_total: int
    auc: float
    """Of the margin to the reject cut, normal (k = 0) vs severe (k = 100)."""
    confusion: dict[tuple[str, str], int]
    """(true grade, graded) -> runs, over every k."""
    meshes: int
    unscored: int = 0
    """Runs measured outside the fitted range: unscored, so diverted (right for a severe run, wrong for a normal
    one)."""

    @property
    def right(self) -> int:
        return self.normal_right + self.severe_right

    @property
    def total(self) -> int:
        return self.normal_total + self.severe_total

    @property
    def severe_passed(self) -> int:
        """Severe (k = 100) runs graded normal: the misses a line cannot afford."""
        return self.severe_total - self.severe_right

    @property
    def grade_right(self) -> int:
        return sum(n for (truth, graded), n in self.confusion.items() if truth == graded)

    @property
    def grade_total(self) -> int:
        return sum(self.confusion.values())


def summarise(runs: Sequence[GradedRun]) -> GradeSummary:
    """Reject accuracy, AUC and three-class confusion of graded runs."""
    normal = [r for r in runs if r.k == NORMAL_K]
    severe = [r for r in runs if r.k == SEVERE_K]
    confusion: dict[tuple[str, str], int] = {}
    for r in runs:
        key = (true_grade(r.k), r.grade)
        confusion[key] = confusion.get(key, 0) + 1
    return GradeSummary(
        normal_right=sum(r.label == LABEL_NORMAL for r in normal), normal_total=len(normal),
        severe_right=sum(r.label != LABEL_NORMAL for r in severe), severe_total=len(severe),
        auc=roc([r.margin for r in normal], [r.margin for r in severe])[2], confusion=confusion,
        meshes=len({r.mesh for r in runs}), unscored=sum(r.label == LABEL_UNSCORED for r in runs))
