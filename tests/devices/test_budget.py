"""Reply timeouts from measured round trips; the error budget's leaky bucket."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from riderlive.devices.budget import ErrorBudget, ReplyTimer

excess = st.floats(min_value=0.0, max_value=100.0, allow_nan=False)


@given(st.lists(excess, min_size=1, max_size=200), st.integers(0, 6))
def test_the_allowance_stays_between_floor_and_ceiling(samples: list[float], misses: int) -> None:
    timer = ReplyTimer(floor_ms=2.0, ceiling_ms=25.0)
    for s in samples:
        timer.observe(s)
    for _ in range(misses):
        timer.missed()
    assert 2.0 <= timer.allowance_ms() <= 25.0
    assert timer.timeout_ms(3.0) == 3.0 + timer.allowance_ms()


def test_the_allowance_follows_the_measured_delays() -> None:
    quiet = ReplyTimer(floor_ms=1.0, ceiling_ms=50.0)
    for _ in range(50):
        quiet.observe(0.3)
    assert quiet.allowance_ms() == 1.0  # steady, fast replies: the floor
    loaded = ReplyTimer(floor_ms=1.0, ceiling_ms=50.0)
    for i in range(200):
        loaded.observe(2.0 if i % 2 else 8.0)  # a busy host: replies 2-8 ms late
    # srtt -> 5 ms, rttvar -> 3 ms: srtt + 4 rttvar = 17 ms (hand-computed limit of the EWMAs)
    assert abs(loaded.allowance_ms() - 17.0) < 1.0
    assert loaded.allowance_ms() > 8.0  # every one of those replies would have been in time


def test_a_miss_backs_off_and_a_reply_resets_it() -> None:
    timer = ReplyTimer(floor_ms=2.0, ceiling_ms=100.0)
    for _ in range(20):
        timer.observe(0.0)
    base = timer.allowance_ms()
    timer.missed()
    assert timer.allowance_ms() == 2 * base
    timer.missed()
    timer.missed()
    assert timer.allowance_ms() == 4 * base  # max_backoff
    timer.observe(0.0)
    assert timer.allowance_ms() == base


@given(st.lists(st.booleans(), min_size=1, max_size=2000))
def test_the_budget_holds_while_good_reads_keep_up(outcomes: list[bool]) -> None:
    """Spent exactly when, somewhere, failures outnumbered good reads by more than the burst."""
    budget = ErrorBudget(burst=20.0, credit=1.0)
    level, expect_spent = 0.0, False
    for failed in outcomes:
        if failed:
            level += 1.0
            spent = budget.fail()
            expect = level > 20.0
            assert spent == expect
            expect_spent |= expect
        else:
            level = max(0.0, level - 1.0)
            budget.ok()
    assert budget.failures == sum(outcomes)


def test_scattered_misses_never_spend_it_persistent_ones_do() -> None:
    budget = ErrorBudget(burst=20.0, credit=1.0)
    for i in range(100_000):  # a loaded host: 30 % of the reads miss, for ever
        assert not (budget.fail() if i % 10 < 3 else budget.ok())
    budget.reset()
    spent_after = next(n for n in range(1, 1000) if budget.fail())  # a corrupted bus: every read fails
    assert spent_after == 21
    assert budget.failures_to_spend(0.3) == float("inf")
    assert budget.failures_to_spend(1.0) == 20.0
