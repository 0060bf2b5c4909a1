"""A graded fillet as the woody_msgs/FilletVerdict the grader publishes.

A plain function, so the grader node and the offline replay (tools/replay_evaluation.py) put every field, the
cut at the fillet's own conditions and the unscored NaNs, into the message the same way.
"""

from __future__ import annotations

import math

from woody_common.stamps import seconds_to_stamp
from woody_msgs.msg import FilletVerdict
from woody_vision.grader_core import GradedFillet
from woody_vision.grading import FilletConditions, GradingRules

LABELS = {"normal": FilletVerdict.CLASS_NORMAL, "woody": FilletVerdict.CLASS_WOODY,
          "unscored": FilletVerdict.CLASS_UNSCORED}


def verdict_message(fillet: GradedFillet, rules: GradingRules, frame_id: str, now: float) -> FilletVerdict:
    """The fillet's verdict, stamped when its centroid crossed the roller edge (``ShapeResult.stamp``; ``now``, the
    grader's sim time, when the result has none)."""
    shape, nan = fillet.shape, math.nan
    conditions = fillet.conditions or FilletConditions(nan)
    cut = rules.threshold.at(conditions)
    msg = FilletVerdict(
        fillet_id=fillet.fillet_id, lane=max(fillet.lane, 0), classification=LABELS[fillet.label],
        grade=fillet.grade, unscored_reason=fillet.reason, score=_finite_or_nan(fillet.score),
        line_phi=_finite_or_nan(shape.line_phi), line_fraction=shape.line_fraction,
        speed=_finite_or_nan(conditions.speed_mps), leading_end=shape.leading_end,
        turn=_finite_or_nan(conditions.turn_deg), length=_finite_or_nan(conditions.length_m),
        rejected_frames=shape.rejected_frames, phi=_finite_or_nan(shape.phi),
        hu_term=_finite_or_nan(shape.hu_term), solidity_term=_finite_or_nan(shape.solidity_term),
        threshold=cut, frames_in_window=shape.frames,
        moderate_threshold=cut if rules.severe_threshold else nan,
        severe_threshold=rules.severe_threshold.at(conditions) if rules.severe_threshold else nan)
    msg.header.stamp = seconds_to_stamp(shape.stamp if shape.stamp is not None else now)
    msg.header.frame_id = frame_id
    if shape.reference_stamp is not None:
        msg.reference_stamp = seconds_to_stamp(shape.reference_stamp)
    return msg


def _finite_or_nan(value: float | None) -> float:
    """A float field's value: NaN for a value the fillet does not have."""
    return float(value) if value is not None and math.isfinite(value) else math.nan
