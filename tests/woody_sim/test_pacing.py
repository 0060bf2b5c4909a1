"""The producer waits for acknowledgements within its lead, probes with a frame now and then, never waits forever."""

from __future__ import annotations

import pytest

from woody_sim.pacing import LeadLimiter


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def limiter_and_clock(**kwargs) -> tuple[LeadLimiter, FakeClock]:
    clock = FakeClock()
    return LeadLimiter(max_lead_s=0.1, stall_s=2.0, start_s=30.0, probe_s=0.5, clock=clock, **kwargs), clock


def test_waits_only_beyond_the_lead():
    limiter, _ = limiter_and_clock()
    assert not limiter.must_wait(0.1)  # nothing acknowledged yet, but still within the lead
    assert limiter.must_wait(0.1 + 1 / 30)
    limiter.ack(1 / 30)
    assert not limiter.must_wait(0.1 + 1 / 30)
    limiter.ack(0.0)  # a late, older acknowledgement does not move it back
    assert not limiter.must_wait(0.1 + 1 / 30)


def test_a_held_line_lets_one_frame_through_per_probe_time_so_a_lost_frame_cannot_hang_it():
    limiter, clock = limiter_and_clock()
    limiter.ack(0.0)
    clock.t = 0.4
    assert limiter.must_wait(0.2)
    clock.t = 0.5
    assert not limiter.must_wait(0.2)  # the probe frame
    assert limiter.must_wait(0.25)  # the next one waits again ...
    clock.t = 1.0
    assert not limiter.must_wait(0.25)  # ... for another probe time
    assert limiter.stalls == 0


def test_a_silent_consumer_is_given_up_after_the_stall_time_until_it_answers():
    limiter, clock = limiter_and_clock()
    limiter.ack(0.3)
    clock.t = 1.9
    assert not limiter.must_wait(0.5)  # a probe (nothing released for 1.9 s) ...
    assert limiter.must_wait(0.5)  # ... then holding
    clock.t = 2.0
    assert not limiter.must_wait(0.5) and limiter.stalls == 1
    assert not limiter.must_wait(0.9)  # not waited for again ...
    limiter.ack(0.45)
    assert limiter.must_wait(0.9)  # ... until it answers


def test_a_consumer_that_never_answered_is_waited_for_longer_than_one_that_stopped():
    limiter, clock = limiter_and_clock()
    clock.t = 29.9
    limiter.must_wait(0.5)  # a probe
    assert limiter.must_wait(0.5) and limiter.stalls == 0  # still starting: keep holding
    clock.t = 30.0
    assert not limiter.must_wait(0.5) and limiter.stalls == 1


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="max_lead_s"):
        LeadLimiter(0.0)
    with pytest.raises(ValueError, match="probe_s"):
        LeadLimiter(0.1, probe_s=0.0)
