"""The stall classification (service/stall.py) on hand-made observations: a fake clock, no processes."""

from __future__ import annotations

import os

import pytest
from hypothesis import given
from hypothesis import strategies as st

from riderlive.service.stall import Model, Observation, Sched, Verdict, classify, read_sched
from riderlive.service.watch import FROZEN_SLACK_S, CpuReading, cpu_stalls

MODEL = Model(threshold=0.034, longest_excuse=5.0, start_stuck=10.0, start_limit=300.0)
RUNNING = Sched(cpu=10.0, wait=1.0, stopped=False)


def seen(
    age: float | None, *, late: float = 0.0, wait: float = 0.0, stopped: bool = False, **more: float
) -> Observation:
    """The tick at ``now`` = 100 s whose last beat is ``age`` old; ``wait``: run-queue wait since that beat."""
    now = Sched(cpu=10.001, wait=1.0 + wait, stopped=stopped)
    return Observation(now=100.0, woke_late=late, beat_age=age, since_start=50.0, at_beat=RUNNING, sched=now, **more)


def test_a_fresh_heartbeat_is_ok() -> None:
    assert classify(MODEL, seen(0.008)).verdict is Verdict.OK
    assert classify(MODEL, seen(0.034)).verdict is Verdict.OK, "the threshold itself is not a hang"


def test_an_old_heartbeat_with_nothing_to_excuse_it_is_a_hang() -> None:
    finding = classify(MODEL, seen(0.040))
    assert finding.verdict is Verdict.HUNG
    assert finding.age == pytest.approx(0.040) and finding.excused == 0.0
    assert "40 ms" in finding.why


def test_the_supervisors_own_lateness_is_discounted() -> None:
    # It woke 30 ms late: of the 60 ms, 30 are its own; 30 ms left is under the threshold.
    finding = classify(MODEL, seen(0.060, late=0.030))
    assert finding.verdict is Verdict.STALLED
    assert finding.age == pytest.approx(0.030) and finding.excused == pytest.approx(0.030)
    # Late by 10 ms only: 50 ms left, hung.
    assert classify(MODEL, seen(0.060, late=0.010)).verdict is Verdict.HUNG


def test_a_tick_runnable_but_not_run_is_not_hung() -> None:
    # 100 ms without a beat, of which it waited 90 ms on a run queue: the host, not the tick.
    assert classify(MODEL, seen(0.100, wait=0.090)).verdict is Verdict.STALLED
    # Waited 20 ms of 100: 80 ms unexplained.
    assert classify(MODEL, seen(0.100, wait=0.020)).verdict is Verdict.HUNG


def test_overlapping_excuses_are_not_added() -> None:
    # The supervisor late by 40 ms and the tick waiting 40 ms are the same host stall: 80 ms - 40 = 40 > 34.
    assert classify(MODEL, seen(0.080, late=0.040, wait=0.040)).verdict is Verdict.HUNG
    assert classify(MODEL, seen(0.080, late=0.050, wait=0.020)).verdict is Verdict.STALLED


def test_another_processes_stalled_heartbeat_excuses_a_host_stall() -> None:
    assert classify(MODEL, seen(0.090, others_stall=0.070)).verdict is Verdict.STALLED
    assert classify(MODEL, seen(0.090, others_stall=0.020)).verdict is Verdict.HUNG


def test_steal_time_excuses_a_host_stall_but_not_a_stopped_tick() -> None:
    # The hypervisor took a vCPU for 90 of the 100 ms: nothing in the guest ran.
    assert classify(MODEL, seen(0.100, stolen=0.090)).verdict is Verdict.STALLED
    assert classify(MODEL, seen(0.100, stolen=0.030)).verdict is Verdict.HUNG
    assert classify(MODEL, seen(0.100, stolen=0.090, stopped=True)).verdict is Verdict.HUNG


def test_a_stopped_tick_is_excused_only_by_the_supervisors_own_lateness() -> None:
    # SIGSTOP: no run-queue wait counts, nor the guardian's stall; the supervisor's lateness does.
    assert classify(MODEL, seen(0.040, stopped=True, wait=0.040, others_stall=0.040)).verdict is Verdict.HUNG
    assert classify(MODEL, seen(0.040, stopped=True, late=0.020)).verdict is Verdict.STALLED
    assert "SIGSTOP" in classify(MODEL, seen(0.100, stopped=True)).why


def test_starved_too_long_is_a_hang_anyway() -> None:
    finding = classify(MODEL, seen(6.0, wait=5.99))
    assert finding.verdict is Verdict.HUNG and "starved" in finding.why


def test_a_dying_tick_fails_over_at_once() -> None:
    dying = Sched(cpu=10.0, wait=1.0, stopped=False, exiting=True)
    observation = Observation(100.0, 0.0, 0.001, 50.0, RUNNING, dying)
    assert classify(MODEL, observation).verdict is Verdict.DYING


def test_a_starting_tick_is_waited_for_while_it_makes_progress() -> None:
    def starting(since: float, progress_age: float, stopped: bool = False) -> Verdict:
        sched = Sched(cpu=0.5, wait=0.1, stopped=stopped)
        observation = Observation(100.0, 0.0, None, since, None, sched, progress_age=progress_age)
        return classify(MODEL, observation).verdict

    assert starting(since=59.0, progress_age=0.1) is Verdict.STARTING, "slow (a loaded host) but going"
    assert starting(since=200.0, progress_age=9.0) is Verdict.STARTING, "a minute is no reason by itself"
    assert starting(since=20.0, progress_age=10.5) is Verdict.NEVER_STARTED, "no CPU, no wait for 10 s: stuck"
    assert starting(since=301.0, progress_age=0.0) is Verdict.NEVER_STARTED, "the overall limit"
    assert starting(since=5.0, progress_age=5.0, stopped=True) is Verdict.STARTING
    assert starting(since=12.0, progress_age=11.0, stopped=True) is Verdict.NEVER_STARTED


@given(
    age=st.floats(0.0, 10.0),
    late=st.floats(0.0, 10.0),
    wait=st.floats(0.0, 10.0),
    others=st.floats(0.0, 10.0),
)
def test_the_discount_never_exceeds_the_age_nor_the_largest_excuse(
    age: float, late: float, wait: float, others: float
) -> None:
    finding = classify(MODEL, seen(age, late=late, wait=wait, others_stall=others))
    if finding.verdict is Verdict.OK:
        assert age <= MODEL.threshold
        return
    assert 0.0 <= finding.excused <= min(age, max(late, wait, others)) + 1e-12
    assert finding.age == pytest.approx(age - finding.excused)
    if finding.verdict is Verdict.STALLED:
        assert finding.age <= MODEL.threshold and finding.excused <= MODEL.longest_excuse
    else:
        assert finding.verdict is Verdict.HUNG


def test_read_sched_reads_this_process() -> None:
    before = read_sched(os.getpid())
    assert before is not None and not before.stopped and not before.exiting
    sum(range(2_000_000))  # burn a little CPU
    after = read_sched(os.getpid())
    assert after is not None and after.cpu > before.cpu and after.process_cpu >= before.process_cpu
    assert read_sched(2**22 + 7) is None, "no such process"


def test_the_ticks_cpu_standing_still_excuses_a_host_stall_but_not_a_stopped_tick() -> None:
    # Its vCPU taken for 90 of the 100 ms: the tick asleep there was not woken (the steal
    # is added only once the vCPU runs again, so it reads 0 now).
    assert classify(MODEL, seen(0.100, frozen=0.090)).verdict is Verdict.STALLED
    assert classify(MODEL, seen(0.100, frozen=0.030)).verdict is Verdict.HUNG
    assert classify(MODEL, seen(0.100, frozen=0.090, stopped=True)).verdict is Verdict.HUNG
    assert classify(MODEL, seen(0.100, frozen=0.090, stolen=0.090)).excused == pytest.approx(0.090)  # not added


def reading(t: float, *cpus: tuple[float, float]) -> CpuReading:
    return (t, tuple(cpus))


def test_cpu_stalls_by_hand() -> None:
    on = lambda cpu: Sched(cpu=0.0, wait=0.0, stopped=False, processor=cpu)  # noqa: E731
    base = reading(100.0, (50.0, 1.0), (60.0, 2.0))
    # 100 ms later: CPU 0 accounted nothing (taken), CPU 1 all of it; no steal added yet
    now = reading(100.1, (50.0, 1.0), (60.1, 2.0))
    assert cpu_stalls(base, now, on(0)) == pytest.approx((0.0, 0.1 - FROZEN_SLACK_S))
    assert cpu_stalls(base, now, on(1)) == (0.0, 0.0)
    assert cpu_stalls(base, now, on(-1)) == (0.0, 0.0)  # the tick's CPU unknown
    assert cpu_stalls(base, now, None) == (0.0, 0.0)
    assert cpu_stalls(base, now, on(5)) == (0.0, 0.0)  # a CPU the reading does not have
    # once CPU 0 ran again: 90 ms of steal added, 10 ms accounted
    after = reading(100.1, (50.01, 1.09), (60.1, 2.0))
    assert cpu_stalls(base, after, on(0)) == pytest.approx((0.09, 0.1 - 0.01 - FROZEN_SLACK_S))
    assert cpu_stalls(reading(0.0), now, on(0)) == (0.0, 0.0)  # no baseline yet


@given(
    st.floats(0.0, 1.0),
    st.floats(0.0, 1.0),
    st.floats(0.0, 0.5),
    st.integers(-1, 2),
)
def test_standing_still_is_never_more_than_the_wall_time_nor_when_the_cpu_kept_up(
    span: float, accounted: float, steal: float, cpu: int
) -> None:
    base = reading(10.0, (5.0, 0.0), (5.0, 0.0))
    now = reading(10.0 + span, (5.0 + accounted, steal), (5.0 + accounted, steal))
    stolen, frozen = cpu_stalls(base, now, Sched(cpu=0.0, wait=0.0, stopped=False, processor=cpu))
    assert stolen == pytest.approx(steal) and 0.0 <= frozen <= span
    if accounted >= span - FROZEN_SLACK_S or cpu < 0:
        assert frozen == 0.0


def test_read_sched_names_the_cpu_it_last_ran_on() -> None:
    sched = read_sched(os.getpid())
    assert sched is not None and 0 <= sched.processor < (os.cpu_count() or 1)
