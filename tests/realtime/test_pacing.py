"""Deadline pacing: no drift, overruns and skips counted."""

from __future__ import annotations

import time

import pytest

from riderlive.realtime.pacing import (
    LATENESS_BUCKETS,
    PICKUP_GRACE,
    PICKUP_MAX_AGE,
    DeadlineClock,
    bucket_of,
    pickup_until,
)


def test_deadlines_do_not_drift_whatever_the_work_costs() -> None:
    period = 0.002
    clock = DeadlineClock(period=period, start=time.perf_counter())
    for i in range(100):
        deadline, lateness = clock.wait()
        assert lateness >= 0.0
        time.sleep(0.0005 if i % 2 else 0.0)
    assert clock.tick == 100 + clock.skipped
    assert deadline == clock.start + clock.tick * period, "deadline n is start + n * period exactly"


def test_an_overrun_is_counted_and_missed_deadlines_are_skipped() -> None:
    period = 0.002
    clock = DeadlineClock(period=period, start=time.perf_counter())
    clock.wait()
    time.sleep(0.0105)  # miss about five deadlines
    called = time.perf_counter()
    deadline, _ = clock.wait()
    back = time.perf_counter()
    assert clock.overruns == 1
    missed_at_call = int((called - clock.deadline(2)) / period)
    missed_at_return = int((back - clock.deadline(2)) / period)
    assert 4 <= missed_at_call <= clock.skipped <= missed_at_return
    assert deadline == clock.deadline(clock.tick)
    assert deadline > called - period, "after skipping, the tick runs on a fresh deadline, not a stale one"


def test_buckets() -> None:
    assert bucket_of(0.0) == 0
    assert bucket_of(0.0004) == LATENESS_BUCKETS.index(0.0005)
    assert bucket_of(10.0) == len(LATENESS_BUCKETS)


@pytest.mark.parametrize("period", [1.0 / 500.0, 1.0 / 120.0, 1.0 / 1000.0])
def test_the_pickup_waits_only_for_a_frame_received_just_before_the_deadline(period: float) -> None:
    deadline = 100.0
    grace = min(PICKUP_GRACE, 0.15 * period)
    # Received 0.1 ms before the deadline, still being written: wait until deadline + grace.
    assert pickup_until(deadline, deadline - 0.0001, period) == pytest.approx(deadline + grace, abs=1e-12)
    assert pickup_until(deadline, deadline, period) == pytest.approx(deadline + grace, abs=1e-12)
    assert grace <= 0.0003 and grace <= 0.15 * period
    # None on its way, received after the deadline (the next tick's), or a stale note: no wait.
    assert pickup_until(deadline, -1.0, period) == -1.0
    assert pickup_until(deadline, deadline + 1e-6, period) == -1.0
    assert pickup_until(deadline, deadline - PICKUP_MAX_AGE - 1e-6, period) == -1.0
    assert pickup_until(deadline, deadline - PICKUP_MAX_AGE + 1e-6, period) > deadline
