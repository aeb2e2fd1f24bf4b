"""Declared device waits and unrun runnable ticks in the stall classification (service/stall.py):
hand-made observations on a fake clock (seconds), no processes."""

from __future__ import annotations

import os
import threading

import pytest
from hypothesis import given
from hypothesis import strategies as st

from riderlive.service.stall import (
    Finding,
    Model,
    Observation,
    Sched,
    Tally,
    Verdict,
    classify,
    hang_detail,
    io_excuse,
    read_threads,
)
from tests.waiting import wait_until

MODEL = Model(threshold=0.0614)
"""bench3 at 120 Hz: (5 - 1) ticks of 8.33 ms + its longest wait 28.1 ms."""
AT_BEAT = Sched(cpu=10.0, wait=1.0, stopped=False, state="R")
NOW = 100.0


def tick(state: str, ran: float = 0.002, wait: float = 0.0) -> Sched:
    """The tick's main thread now: ``ran`` s on a CPU and ``wait`` s on a run queue since the beat."""
    return Sched(cpu=10.0 + ran, wait=1.0 + wait, stopped=state == "T", state=state)


def seen(age: float, sched: Sched, *, waited: float = 0.0, since: float = 0.0, until: float = 0.0) -> Observation:
    """``age`` s since the beat; ``waited`` s of ended declared waits; an ongoing one from
    ``since`` to ``until`` (relative to now; both 0: none)."""
    io_until = NOW + until if (since or until) else 0.0
    return Observation(
        now=NOW,
        woke_late=0.0,
        beat_age=age,
        since_start=50.0,
        at_beat=AT_BEAT,
        sched=sched,
        io_until=io_until,
        io_since=NOW + since if io_until else 0.0,
        io_waited=waited,
    )


def test_the_soaks_false_hang_asleep_after_its_device_waits_is_excused_and_counted() -> None:
    # Soak (bounded-A run 4): 66 ms without a beat, asleep in poll, 2.2 ms on a CPU; say 40 ms of
    # it in reply waits that timed out: 26 ms left, under the threshold.
    finding = classify(MODEL, seen(0.066, tick("S", ran=0.0022), waited=0.040))
    assert finding.verdict is Verdict.IO_WAIT
    assert finding.excused == pytest.approx(0.040) and finding.age == pytest.approx(0.026)
    assert "40 of them in declared waits" in finding.why
    # The same gap with no declared wait is a hang, as before.
    assert classify(MODEL, seen(0.066, tick("S", ran=0.0022))).verdict is Verdict.HUNG


def test_an_ongoing_wait_counts_only_up_to_its_deadline() -> None:
    # In a wait since 50 ms ago that ends in 5 ms: 50 ms of the 80 excused.
    assert classify(MODEL, seen(0.080, tick("S"), since=-0.050, until=0.005)).verdict is Verdict.IO_WAIT
    # The same wait whose deadline passed 40 ms ago: only its 10 ms up to the deadline count (70 left).
    finding = classify(MODEL, seen(0.080, tick("S"), since=-0.050, until=-0.040))
    assert finding.verdict is Verdict.HUNG


def test_never_past_the_deadline_plus_one_threshold() -> None:
    # A wait declared at the beat whose deadline was D = 30 ms after it: excused until D + threshold.
    def at(age: float) -> Verdict:
        return classify(MODEL, seen(age, tick("S"), since=-age, until=0.030 - age)).verdict

    assert at(0.090) is Verdict.IO_WAIT  # 30 ms excused, 60 ms left
    assert at(0.0913) is Verdict.IO_WAIT
    assert at(0.0915) is Verdict.HUNG  # D + threshold = 91.4 ms


def test_a_tick_spinning_inside_a_wait_is_not_excused() -> None:
    spinning = tick("R", ran=0.065)
    assert io_excuse(MODEL, seen(0.070, spinning, waited=0.040)) == 0.0
    assert classify(MODEL, seen(0.070, spinning, waited=0.040)).verdict is Verdict.HUNG
    # Runnable but mostly asleep (a wait polls its port every 0.2 ms): not spinning.
    assert classify(MODEL, seen(0.070, tick("R", ran=0.010), waited=0.040)).verdict is Verdict.IO_WAIT
    # Uninterruptible I/O is asleep too.
    assert classify(MODEL, seen(0.070, tick("D"), waited=0.040)).verdict is Verdict.IO_WAIT


def test_a_stopped_tick_is_not_excused_by_a_wait() -> None:
    assert classify(MODEL, seen(0.070, tick("T"), waited=0.060)).verdict is Verdict.HUNG


def test_the_io_excuse_is_capped() -> None:
    # Waits after waits: 200 ms of them in a 210 ms gap; at most io_limit (the threshold) is excused.
    assert io_excuse(MODEL, seen(0.210, tick("S"), waited=0.200)) == pytest.approx(MODEL.threshold)
    assert classify(MODEL, seen(0.210, tick("S"), waited=0.200)).verdict is Verdict.HUNG
    wider = Model(threshold=MODEL.threshold, io_limit=0.2)
    assert classify(wider, seen(0.210, tick("S"), waited=0.200)).verdict is Verdict.IO_WAIT


def test_a_runnable_tick_that_was_not_run_is_the_hosts_stall() -> None:
    # Soak (bounded-A run 2): R, 0.0 ms on a CPU for 97 ms, no run-queue wait counted yet.
    finding = classify(MODEL, seen(0.097, tick("R", ran=0.0)))
    assert finding.verdict is Verdict.STALLED
    assert finding.excused == pytest.approx(0.097)
    # R and on a CPU for most of the gap: spinning, hung.
    assert classify(MODEL, seen(0.097, tick("R", ran=0.090))).verdict is Verdict.HUNG
    # A tenth of the gap on a CPU is the bound.
    assert classify(MODEL, seen(0.100, tick("R", ran=0.0101))).verdict is Verdict.HUNG


@given(
    age=st.floats(0.0, 1.0),
    waited=st.floats(0.0, 1.0),
    since=st.floats(-1.0, 0.0),
    length=st.floats(0.0, 1.0),
    ran=st.floats(0.0, 1.0),
    state=st.sampled_from("RSDT"),
    io_limit=st.floats(0.0, 0.5),
)
def test_the_io_excuse_is_bounded(
    age: float, waited: float, since: float, length: float, ran: float, state: str, io_limit: float
) -> None:
    model = Model(threshold=MODEL.threshold, io_limit=io_limit)
    until = since + length
    observation = seen(age, tick(state, ran=ran), waited=waited, since=since, until=until)
    io = io_excuse(model, observation)
    cap = io_limit or model.threshold
    assert 0.0 <= io <= min(age, cap, waited + max(0.0, min(0.0, until) - since)) + 1e-12
    if state == "R" and tick(state, ran=ran).cpu - AT_BEAT.cpu >= 0.5 * age:  # as the kernel's ns add up
        assert io == 0.0, "spinning"
    finding = classify(model, observation)
    if finding.verdict is Verdict.IO_WAIT:
        assert state != "T"
        assert age > model.threshold and age - io <= model.threshold + 1e-12
        assert age <= model.threshold + cap + 1e-12
        if waited == 0.0 and since >= -age:  # only a wait begun after the beat: never past D + one threshold
            assert until >= -model.threshold - 1e-12
    if finding.verdict is Verdict.OK:
        assert age <= model.threshold


def test_the_tally_counts_one_per_gap_and_the_longest() -> None:
    tally = Tally()
    io = Finding(Verdict.IO_WAIT, 0.02, 0.05, "waiting")
    assert tally.add(io, beat=1.0, age=0.070) is not None
    assert tally.add(io, beat=1.0, age=0.080) is None, "the same gap"
    assert tally.add(Finding(Verdict.STALLED, 0.02, 0.03, "host"), beat=1.0, age=0.081) is not None
    assert tally.add(io, beat=2.0, age=0.065) is not None
    assert tally.add(Finding(Verdict.OK), beat=3.0, age=0.001) is None
    assert (tally.io_waits_excused, tally.stalls) == (2, 1)
    assert tally.io_wait_longest == pytest.approx(0.080) and tally.stall_excused_max == pytest.approx(0.03)


def test_a_hang_says_what_the_ticks_threads_were_doing() -> None:
    asleep = threading.Event()
    sleeper = threading.Thread(target=asleep.wait, daemon=True)
    sleeper.start()
    try:
        # The new thread runs until it blocks on the event: then it sleeps.
        wait_until(lambda: any(t.state == "S" for t in read_threads(os.getpid())[1:]), 10.0, "no thread asleep")
        threads = read_threads(os.getpid())
        assert threads[0].tid == os.getpid() and threads[0].state == "R", "the main thread first, reading"
        observation = seen(0.080, tick("S"), waited=0.010, since=-0.005, until=0.020)
        text = hang_detail(classify(MODEL, observation), observation, os.getpid())
        assert text.startswith("hung (no heartbeat for 80 ms") and "main thread R in" in text
        assert "10.0 ms in device waits that ended" in text and "from -5.0 ms until +20.0 ms" in text
        assert "other threads: " in text and " S " in text
        gone = 2**22 + 7
        assert read_threads(gone) == []
        assert "threads: gone" in hang_detail(classify(MODEL, observation), observation, gone)
    finally:
        asleep.set()
