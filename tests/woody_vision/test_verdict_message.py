"""woody_vision.verdict_message: every field of a verdict, scored and unscored, and back through the report."""

from __future__ import annotations

import math

from woody_common.calibration import resolved_calibration
from woody_common.stamps import stamp_to_seconds
from woody_experiments.messages import verdict_from_msg
from woody_msgs.msg import FilletVerdict
from woody_vision.grader_core import GradedFillet, calibrated_rules
from woody_vision.grading import FilletConditions
from woody_vision.shape_score import ShapeResult
from woody_vision.verdict_message import verdict_message

RULES = calibrated_rules(resolved_calibration())


def _shape(status: str, reason: str = "", stamp: float | None = 4.5, line_phi: float = math.nan) -> ShapeResult:
    return ShapeResult(status, reason, phi=math.nan, hu_term=math.nan, solidity_term=math.nan, frames=7,
                       stamp=stamp, aspect_ratio=2.0, reference_stamp=4.0 if stamp else None, line_phi=line_phi,
                       leading_end="narrow", rejected_frames=1)


def test_scored_fillet_carries_its_cut_at_its_conditions():
    conditions = FilletConditions(speed_mps=0.66, turn_deg=10.0)
    fillet = GradedFillet(3, 1, _shape("scored", line_phi=2.0), "woody", "severe", score=2.0, conditions=conditions)
    msg = verdict_message(fillet, RULES, "top_camera_optical_frame", now=9.0)
    assert msg.classification == FilletVerdict.CLASS_WOODY and msg.grade == "severe"
    assert msg.threshold == RULES.threshold.at(conditions) == msg.moderate_threshold
    assert msg.severe_threshold == RULES.severe_threshold.at(conditions)
    assert (msg.speed, msg.turn, msg.rejected_frames, msg.frames_in_window) == (0.66, 10.0, 1, 7)
    assert stamp_to_seconds(msg.header.stamp) == 4.5 and stamp_to_seconds(msg.reference_stamp) == 4.0
    assert msg.header.frame_id == "top_camera_optical_frame"


def test_unscored_fillet_without_a_window_is_stamped_now_with_nan_scores():
    fillet = GradedFillet(4, -1, _shape("unscored", "track ended before the evaluation window closed", stamp=None),
                          "unscored", "")
    msg = verdict_message(fillet, RULES, "", now=9.0)
    assert msg.classification == FilletVerdict.CLASS_UNSCORED and msg.lane == 0
    assert math.isnan(msg.score) and math.isnan(msg.line_phi) and math.isnan(msg.speed)
    assert stamp_to_seconds(msg.header.stamp) == 9.0
    verdict = verdict_from_msg(msg)
    assert verdict.classification == "unscored" and verdict.reason == fillet.reason and verdict.stamp == 9.0
