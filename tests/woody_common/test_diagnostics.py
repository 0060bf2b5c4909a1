"""woody_common.diagnostics: a node's health as a DiagnosticStatus."""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticStatus

from woody_common.diagnostics import ERROR, OK, WARN, Health, status_of


def test_a_health_becomes_one_status_named_by_its_node_with_its_figures_as_text():
    status = status_of("/line2/grader", Health(WARN, "12 verdicts, 1 unscored", {"verdicts": 12, "lag (s)": 0.123456}))
    assert status.level == DiagnosticStatus.WARN and status.name == "/line2/grader"
    assert status.message == "12 verdicts, 1 unscored" and status.hardware_id == "woody"
    assert [(v.key, v.value) for v in status.values] == [("verdicts", "12"), ("lag (s)", "0.1235")]


def test_the_levels_are_diagnostic_msgs_own():
    assert (OK, WARN, ERROR) == (DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR)
    assert status_of("n", Health(ERROR, "waiting for camera_info")).values == []
