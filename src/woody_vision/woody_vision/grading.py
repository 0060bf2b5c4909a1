"""Woody-breast decision from the top-down shape score Φ.

A stiff (woody) fillet keeps its outline as it crosses the roller edge, so it
scores a LOW Φ; a normal, flexible fillet drapes and scores high (paper, 100 FPM:
normal k=0 Φ≈19, severe k=100 Φ≈5.4). Hence ``phi < threshold`` means woody.

The optional three-way grade uses its own two boundaries, independent of the
binary reject threshold: 'normal' for Φ ≥ moderate_threshold, 'moderate' for
severe_threshold ≤ Φ < moderate_threshold, 'severe' below severe_threshold.
``moderate_threshold`` defaults to ``threshold``.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

LABEL_NORMAL = "normal"
LABEL_WOODY = "woody"
GRADE_NORMAL = "normal"
GRADE_MODERATE = "moderate"
GRADE_SEVERE = "severe"


@dataclass(frozen=True)
class Classification:
    """Decision for one fillet."""

    label: str
    """'normal' or 'woody' (the reject decision)."""
    grade: str | None
    """'normal', 'moderate' or 'severe'; None when the rules have no grade thresholds."""


@dataclass(frozen=True)
class GradingRules:
    """Thresholds on Φ; validated on construction."""

    threshold: float
    """The binary cut; the calibrated one is in config/calibration.yaml (`woody calibrate`)."""
    moderate_threshold: float | None = None
    severe_threshold: float | None = None

    def __post_init__(self) -> None:
        _require_positive_finite("threshold", self.threshold)
        if self.moderate_threshold is not None and self.severe_threshold is None:
            raise ValueError("moderate_threshold needs severe_threshold as well: the grade has two boundaries")
        if self.severe_threshold is None:
            return
        _require_positive_finite("severe_threshold", self.severe_threshold)
        if self.moderate_threshold is not None:
            _require_positive_finite("moderate_threshold", self.moderate_threshold)
        if not self.severe_threshold < self.grade_moderate_threshold:
            raise ValueError(
                f"severe_threshold ({self.severe_threshold}) must be below the moderate boundary "
                f"({self.grade_moderate_threshold}): severe fillets are stiffer and score lower Φ"
            )

    @property
    def grade_moderate_threshold(self) -> float:
        """The effective normal/moderate boundary (``moderate_threshold`` or ``threshold``)."""
        return self.threshold if self.moderate_threshold is None else self.moderate_threshold

    def is_woody(self, phi: float) -> bool:
        """True when Φ is below the reject threshold."""
        _require_finite_phi(phi)
        return phi < self.threshold

    def grade(self, phi: float) -> str | None:
        """Three-way grade of Φ, or None without grade thresholds."""
        _require_finite_phi(phi)
        if self.severe_threshold is None:
            return None
        if phi < self.severe_threshold:
            return GRADE_SEVERE
        if phi < self.grade_moderate_threshold:
            return GRADE_MODERATE
        return GRADE_NORMAL

    def classify(self, phi: float) -> Classification:
        """Binary label and optional grade of a shape score."""
        return Classification(label=LABEL_WOODY if self.is_woody(phi) else LABEL_NORMAL, grade=self.grade(phi))


def _require_positive_finite(name: str, value: float) -> None:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a number, got {value!r}")
    if not math.isfinite(value) or value <= 0.0:
        raise ValueError(f"{name} must be a finite number > 0, got {value}")


def _require_finite_phi(phi: float) -> None:
    if not math.isfinite(phi):
        raise ValueError(f"phi must be finite, got {phi}: unscored fillets cannot be classified")
