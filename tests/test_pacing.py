"""The producer waits for acknowledgements within its lead, and never forever."""

from __future__ import annotations

import pytest

from woody_sim.pacing import LeadLimiter


def test_waits_only_beyond_the_lead_and_gives_up_after_the_stall_time():
    limiter = LeadLimiter(max_lead_s=0.1, stall_s=2.0, start_s=30.0)
    assert not limiter.must_wait(0.1, 0.0)  # nothing acknowledged yet, but still within the lead
    assert limiter.must_wait(0.1 + 1 / 30, 0.0)
    limiter.ack(1 / 30)
    assert not limiter.must_wait(0.1 + 1 / 30, 0.0)
    limiter.ack(0.0)  # a late, older acknowledgement does not move it back
    assert not limiter.must_wait(0.1 + 1 / 30, 0.0)
    assert limiter.must_wait(0.5, 1.9) and not limiter.must_wait(0.5, 2.0)
    assert not limiter.must_wait(0.6, 0.0)  # a silent consumer is not waited for again ...
    limiter.ack(0.45)
    assert limiter.must_wait(0.6, 0.0)  # ... until it answers
    assert limiter.stalls == 1


def test_a_consumer_that_never_answered_is_waited_for_longer_than_one_that_stopped():
    limiter = LeadLimiter(max_lead_s=0.1, stall_s=2.0, start_s=30.0)
    assert limiter.must_wait(0.5, 29.0) and limiter.stalls == 0  # still starting: keep holding
    assert not limiter.must_wait(0.5, 30.0) and limiter.stalls == 1


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="max_lead_s"):
        LeadLimiter(0.0)
    with pytest.raises(ValueError, match="start_s"):
        LeadLimiter(0.1, start_s=0.0)
