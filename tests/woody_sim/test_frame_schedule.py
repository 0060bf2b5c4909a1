"""FrameSchedule: camera frames fall on the steps line_sim renders, each camera at its own rate."""

import pytest

from woody_sim.frame_schedule import FrameSchedule

DT = 1.0 / 480.0


def due_steps(schedule: FrameSchedule, steps: int) -> tuple[list[int], list[int]]:
    top, side = [], []
    for step in range(steps):
        t, s = schedule.due(step * DT)
        top += [step] * t
        side += [step] * s
    return top, side


def test_cameras_are_due_every_period_from_time_zero():
    top, side = due_steps(FrameSchedule(1 / 30, 1 / 60), 49)
    assert top == [0, 16, 32, 48] and side == [0, 8, 16, 24, 32, 40, 48]


def test_a_rate_that_does_not_divide_the_step_rate_falls_on_the_next_step():
    top, side = due_steps(FrameSchedule(1 / 30, 1 / 200), 12)
    assert side == [0, 3, 5, 8, 10]  # 0, 2.4, 4.8, 7.2, 9.6 steps, rounded up


def test_without_a_side_camera_only_the_top_is_due_and_next_time_follows_it():
    schedule = FrameSchedule(1 / 30, None)
    assert due_steps(schedule, 17) == ([0, 16], [])
    assert schedule.next_time == pytest.approx(2 / 30)


def test_next_time_is_the_earlier_camera():
    schedule = FrameSchedule(1 / 30, 1 / 60)
    schedule.due(0.0)
    assert schedule.next_time == pytest.approx(1 / 60)
