"""Woody-breast decision from a shape score, with cuts that follow the measured line conditions.

A stiff (woody) fillet keeps its outline as it crosses the roller edge, so it
scores a LOW shape score; a normal, flexible fillet drapes and scores high
(paper, 100 FPM: normal k=0 Φ≈19, severe k=100 Φ≈5.4). Hence a fillet is
woody when its score is strictly below the cut.

A cut (:class:`Cut`) may depend on what the top camera measures of each
fillet: ln(cut) = ln(base) + speed_slope · (v − v_ref) + blunt_offset · b
+ turn_slope · θ + length_slope · (L − L_ref), with v the fillet's measured
speed (m/s), v_ref 100 FPM, b = 1 when it travels blunt end first, θ how far
(degrees) its long axis lies turned from the flow, and L its body length (m),
L_ref 0.19 m. A fillet drapes less at a higher speed (it leaves the roller in
a flatter arc), a blunt leading end bends less than a tapered one, and a
turned fillet crosses the edge corner first, for normal and woody meat
alike, so one constant cut cannot fit a line whose speed and fillets vary.
Unknown measurements (NaN) count as the reference values. `woody calibrate`
fits two cuts: the reject cut (normal vs severe) and the grade's
moderate/severe cut. A constant cut (every slope 0) is the paper's single
threshold.

The three-way grade refines the reject decision: 'normal' at or above the reject
cut, 'moderate' between it and the severe cut, 'severe' below the severe cut.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from woody_common.line import REFERENCE_SPEED_MPS

LABEL_NORMAL = "normal"
LABEL_WOODY = "woody"
LABEL_UNSCORED = "unscored"
GRADE_NORMAL = "normal"
GRADE_MODERATE = "moderate"
GRADE_SEVERE = "severe"

THRESHOLD_RANGE = (0.001, 1000.0)
"""The paper score's threshold and a constant line cut are within this range, wherever they are given."""


REFERENCE_LENGTH_M = 0.19
"""Body length at which a cut takes its base (a typical fillet)."""


@dataclass(frozen=True)
class FilletConditions:
    """What the decision may depend on, as measured for one fillet."""

    speed_mps: float = REFERENCE_SPEED_MPS
    blunt_first: bool = False
    turn_deg: float = 0.0
    length_m: float = REFERENCE_LENGTH_M


TIDY = FilletConditions()
"""The paper's line: 100 FPM, narrow end first."""


@dataclass(frozen=True)
class Cut:
    """A cut on the shape score, following the measured conditions (module doc)."""

    base: float
    """The cut at 100 FPM, narrow end first."""
    speed_slope: float = 0.0
    """d ln(cut) / dv, per m/s."""
    blunt_offset: float = 0.0
    """Added to ln(cut) for a fillet travelling blunt end first."""
    turn_slope: float = 0.0
    """d ln(cut) / dθ, per degree turned from the flow."""
    length_slope: float = 0.0
    """d ln(cut) / dL, per metre of body length."""

    def __post_init__(self) -> None:
        _require_positive_finite("cut base", self.base)
        for name in CUT_TERMS[1:]:
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"cut {name} must be finite, got {getattr(self, name)}")

    @classmethod
    def of(cls, value: Cut | float | list | tuple) -> Cut:
        """A cut from a number (constant), a list in :data:`CUT_TERMS` order or a cut."""
        if isinstance(value, Cut):
            return value
        if isinstance(value, (list, tuple)):
            if len(value) != len(CUT_TERMS):
                raise ValueError(f"a cut is [{', '.join(CUT_TERMS)}], got {list(value)}")
            return cls(*(float(v) for v in value))
        _require_positive_finite("threshold", value)
        return cls(float(value))

    def as_list(self) -> list[float]:
        return [getattr(self, name) for name in CUT_TERMS]

    def at(self, conditions: FilletConditions = TIDY) -> float:
        """The cut's value for a fillet measured under ``conditions``."""
        return self.base * math.exp(float(np.dot(self.as_list()[1:], covariates(conditions))))


CUT_TERMS = ("base", "speed_slope", "blunt_offset", "turn_slope", "length_slope")
"""A cut as a list (a ROS parameter, a calibration entry): these fields in this order."""


def covariates(conditions: FilletConditions) -> list[float]:
    """(v − v_ref, blunt, θ, L − L_ref) of measured conditions; a NaN measurement counts as the reference."""
    def known(value: float, reference: float) -> float:
        return value if math.isfinite(value) else reference

    return [known(conditions.speed_mps, REFERENCE_SPEED_MPS) - REFERENCE_SPEED_MPS, float(bool(conditions.blunt_first)),
            known(conditions.turn_deg, 0.0), known(conditions.length_m, REFERENCE_LENGTH_M) - REFERENCE_LENGTH_M]


@dataclass(frozen=True)
class Classification:
    """Decision for one fillet."""

    label: str
    """'normal' or 'woody' (the reject decision)."""
    grade: str | None
    """'normal', 'moderate' or 'severe'; None when the rules have no grade cuts."""
    threshold: float
    """The reject cut's value for this fillet."""


@dataclass(frozen=True)
class GradingRules:
    """Cuts on the shape score (numbers or :class:`Cut`); validated on construction.

    The grade refines the reject decision, never contradicts it: a fillet the
    reject cut passes grades normal; one it diverts grades moderate, or severe
    below the severe cut. A gate and a person reading the grade hear one story.
    """

    threshold: Cut
    """The reject cut, also the grade's normal/moderate boundary; the calibrated one is in config/calibration.yaml
    (`woody calibrate`)."""
    severe_threshold: Cut | None = None
    """The grade's moderate/severe boundary, below the reject cut; None: no grade."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "threshold", Cut.of(self.threshold))
        if self.severe_threshold is None:
            return
        object.__setattr__(self, "severe_threshold", Cut.of(self.severe_threshold))
        for conditions in (TIDY, FilletConditions(blunt_first=True)):
            if not self.severe_threshold.at(conditions) < self.threshold.at(conditions):
                raise ValueError(
                    f"severe_threshold ({self.severe_threshold.at(conditions):g}) must be below the reject cut "
                    f"({self.threshold.at(conditions):g}): severe fillets score lower")

    def is_woody(self, score: float, conditions: FilletConditions = TIDY) -> bool:
        """True when the score is strictly below the reject cut for these conditions (:func:`is_woody_array`)."""
        _require_finite_score(score)
        return bool(is_woody_array(score, self.threshold.at(conditions)))

    def grade(self, score: float, conditions: FilletConditions = TIDY) -> str | None:
        """Three-way grade of the score, or None without grade cuts."""
        _require_finite_score(score)
        if self.severe_threshold is None:
            return None
        if not self.is_woody(score, conditions):
            return GRADE_NORMAL
        return GRADE_SEVERE if score < self.severe_threshold.at(conditions) else GRADE_MODERATE

    def classify(self, score: float, conditions: FilletConditions = TIDY) -> Classification:
        """Reject label, optional grade and the reject cut applied."""
        return Classification(label=LABEL_WOODY if self.is_woody(score, conditions) else LABEL_NORMAL,
                              grade=self.grade(score, conditions), threshold=self.threshold.at(conditions))


SPEED_SLACK = 0.05
"""A measured speed may lie this fraction beyond the fitted range (the measurement's own error)."""
LENGTH_SLACK = 0.15
"""A measured body length may lie this fraction beyond the fitted range: the calibration lays each of its meshes
once per condition, so its lengths sample the line's size spread (x0.85-1.15 on a messy line) sparsely, and the
cut's length term moves it by about 5 % per centimetre."""
TURN_SLACK_DEG = 2.0
"""A measured turn may lie this far beyond the largest turn fitted (degrees)."""
RANGE_TERMS = ("speed_min_mps", "speed_max_mps", "turn_max_deg", "length_min_m", "length_max_m")
"""A fitted range as a list (a ROS parameter, a calibration entry): these fields in this order."""


@dataclass(frozen=True)
class FittedRange:
    """The measured conditions the cuts were fitted on. Outside them a cut is extrapolated and may pass a woody
    fillet (at 400 FPM every one), so the grader leaves such a fillet unscored: the gate diverts it."""

    speed_min_mps: float
    speed_max_mps: float
    turn_max_deg: float
    length_min_m: float
    length_max_m: float

    def __post_init__(self) -> None:
        values = self.as_list()
        if not all(math.isfinite(v) and v >= 0.0 for v in values):
            raise ValueError(f"a fitted range is [{', '.join(RANGE_TERMS)}], finite and >= 0, got {values}")
        if self.speed_min_mps > self.speed_max_mps or self.length_min_m > self.length_max_m:
            raise ValueError(f"a fitted range's minimum exceeds its maximum: {values}")

    @classmethod
    def of(cls, value: FittedRange | list | tuple) -> FittedRange:
        if isinstance(value, FittedRange):
            return value
        if len(value) != len(RANGE_TERMS):
            raise ValueError(f"a fitted range is [{', '.join(RANGE_TERMS)}], got {list(value)}")
        return cls(*(float(v) for v in value))

    def as_list(self) -> list[float]:
        return [getattr(self, name) for name in RANGE_TERMS]

    def outside(self, conditions: FilletConditions) -> str:
        """Why the measured ``conditions`` lie outside the range ('' when inside; an unmeasured value is inside)."""
        speed, turn, length = conditions.speed_mps, conditions.turn_deg, conditions.length_m
        low, high = 1.0 - SPEED_SLACK, 1.0 + SPEED_SLACK
        if not self.speed_min_mps * low <= speed <= self.speed_max_mps * high and math.isfinite(speed):
            return _beyond("speed", f"{speed:.2f} m/s", f"{self.speed_min_mps:.2f}-{self.speed_max_mps:.2f} m/s")
        if turn > self.turn_max_deg + TURN_SLACK_DEG:
            return _beyond("turn", f"{turn:.0f} deg", f"0-{self.turn_max_deg:.0f} deg")
        low, high = 1.0 - LENGTH_SLACK, 1.0 + LENGTH_SLACK
        if not self.length_min_m * low <= length <= self.length_max_m * high and math.isfinite(length):
            return _beyond("body length", f"{length:.3f} m", f"{self.length_min_m:.3f}-{self.length_max_m:.3f} m")
        return ""


def _beyond(what: str, measured: str, fitted: str) -> str:
    return f"outside the calibration: measured {what} {measured}, the cuts were fitted on {fitted}"


def fitted_range_of(conditions: list[FilletConditions]) -> FittedRange:
    """The range a set of measured conditions spans (the rows a calibration fitted its cuts on)."""
    speeds = [c.speed_mps for c in conditions if math.isfinite(c.speed_mps)]
    turns = [c.turn_deg for c in conditions if math.isfinite(c.turn_deg)]
    lengths = [c.length_m for c in conditions if math.isfinite(c.length_m)]
    if not (speeds and turns and lengths):
        raise ValueError("a fitted range needs rows with a measured speed, turn and length")
    return FittedRange(min(speeds), max(speeds), max(turns), min(lengths), max(lengths))


def is_woody_array(scores, threshold) -> np.ndarray:
    """The reject rule, element-wise: woody where the score is strictly below the cut (stiff fillets deform
    less, so they score lower). ``scores`` and ``threshold`` broadcast against each other (numpy); the one
    place the rule is written, for a fillet (:meth:`GradingRules.is_woody`) and for the reports' arrays."""
    return np.asarray(scores, dtype=float) < np.asarray(threshold, dtype=float)


def _require_positive_finite(name: str, value: float) -> None:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a number, got {value!r}")
    if not math.isfinite(value) or value <= 0.0:
        raise ValueError(f"{name} must be a finite number > 0, got {value}")


def _require_finite_score(score: float) -> None:
    if not math.isfinite(score):
        raise ValueError(f"the score must be finite, got {score}: unscored fillets cannot be classified")
