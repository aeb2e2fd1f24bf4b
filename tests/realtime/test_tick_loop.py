"""The tick loop in-process: a failing or non-finite step repeats the last good frame."""

from __future__ import annotations

import dataclasses
import math
import multiprocessing
import os
import time

import pytest

from riderlive.realtime import layout as L
from riderlive.realtime.core import Driver, TickResult, Timing
from riderlive.realtime.counters import COUNTERS
from riderlive.realtime.record import RecordLayout
from riderlive.realtime.setup import TickSetup
from riderlive.realtime.shm import SharedBlob, SharedCounters, SharedRing
from riderlive.realtime.tick import TickLoop
from riderlive.rules import RuleParams
from riderlive.rules.animator import AnimatorLayer


@pytest.fixture
def loop():
    shared = [
        SharedRing(64, L.INPUT_WIDTH),
        SharedRing(64, RecordLayout().width),
        SharedCounters(COUNTERS),
        SharedBlob(),
    ]
    names = dict(zip(("input", "output", "counters", "status"), (s.name for s in shared), strict=True))
    setup = TickSetup(
        rate=100.0,
        start=time.perf_counter(),
        timing=Timing(),
        params=RuleParams(),
        animator=AnimatorLayer(),
        length_scale=25.0,
        shm_names=names,
    )
    _ours, theirs = multiprocessing.Pipe()
    read_fd, write_fd = os.pipe()
    tick = TickLoop(setup, theirs, write_fd, None)
    yield tick
    tick.close()
    for s in shared:
        s.close()
    os.close(read_fd)
    os.close(write_fd)


def test_a_raising_step_repeats_the_last_good_frame(loop: TickLoop) -> None:
    good = loop._step(0.01)
    assert all(math.isfinite(v) for v in good.rider)

    def broken(now: float) -> TickResult:
        raise ZeroDivisionError("boom")

    loop.core.step = broken  # type: ignore[method-assign]
    assert loop._step(0.02) is good
    assert loop.counter.step_errors == 1
    assert "boom" in loop.events[-1]


def test_a_non_finite_rider_never_leaves_the_tick(loop: TickLoop) -> None:
    nan = TickResult(Driver.INPUT, 0.0, 1, [0.0] * L.N_HORSE, [math.nan] * L.N_RIDER)
    loop.core.step = lambda now: nan  # type: ignore[method-assign]
    first = loop._step(0.0)
    assert first.driver is Driver.NEUTRAL and first.rider == loop.core.neutral_rider
    assert loop.counter.nonfinite_outputs == 1


def test_the_phase_lock_follows_horse_frames_of_the_driver_only_and_moves_the_clock(loop: TickLoop) -> None:
    """The tick's edge of ``realtime/phase_lock.py``: the driving producer's horse frames lock
    the clock's phase; a saddle input never does, and without input the clock is untouched."""
    from riderlive.realtime.layout import InputKind
    from riderlive.realtime.pacing import DeadlineClock

    period = 1.0 / loop.setup.rate
    counter = loop.counter

    def run(kind: InputKind, driver: Driver, seconds: float = 3.0) -> DeadlineClock:
        clock = DeadlineClock(period=period, start=loop.setup.start)
        loop.phase.start(0.0)
        loop.core.input_kind, loop.core.driver, loop.core.producer = kind, driver, 5
        frame = 0  # frame k arrives at k * period + 4 ms (engine seconds), taken by the first deadline after it
        for n in range(1, int(seconds / period)):
            deadline = clock.deadline(n) - loop.setup.start
            taken = []
            while frame * period + 0.004 <= deadline:
                taken.append(frame * period + 0.004)
                frame += 1
            loop._follow_phase(clock, deadline, taken)
        return clock

    clock = run(InputKind.SADDLE, Driver.INPUT)
    assert clock.start == loop.setup.start and not loop.phase.state.locked and counter.phase_slews == 0
    clock = run(InputKind.HORSE, Driver.NEUTRAL)  # frames of a producer that does not drive
    assert clock.start == loop.setup.start and not loop.phase.state.locked
    clock = run(InputKind.HORSE, Driver.INPUT)
    assert loop.phase.state.locked and counter.phase_locked == 1.0 and counter.phase_locks == 1
    assert clock.start - loop.setup.start == pytest.approx(loop.phase.state.offset, abs=1e-9)
    # Frames arrive 4 ms into each 10 ms period: the deadlines moved to 4 ms + the margin.
    assert loop.phase.state.offset % period == pytest.approx(0.004 + loop.setup.phase_margin, abs=2e-5)
    assert counter.phase_lead == pytest.approx(loop.setup.phase_margin, abs=2e-5)
    status = loop.status()["phase_lock"]
    assert status["locked"] and status["locks"] == 1 and status["harmonic"] == 1 and status["resultant"] > 0.99
    assert counter.phase_slews == loop.phase.state.slews > 0


def test_a_tick_built_from_another_record_layout_refuses_to_start(loop: TickLoop) -> None:
    """The web process's setup says the records carry a tail this tick does not run: refused, both named."""
    from riderlive.realtime.record import LayoutMismatch

    setup = dataclasses.replace(loop.setup, layout=RecordLayout(("tail_00.rx",), loop.layout.part_channels))
    _ours, theirs = multiprocessing.Pipe()
    with pytest.raises(LayoutMismatch, match=r"the web process's setup has .*tail_00.rx.*the tick has"):
        TickLoop(setup, theirs, loop.notify_fd, None)
    narrow = SharedRing(64, RecordLayout.rider.stop)  # a ring made for records without the rider parts
    try:
        names = {**loop.setup.shm_names, "output": narrow.name}
        with pytest.raises(LayoutMismatch, match=r"the output ring has 84 slots a record, the tick's layout 99 slots"):
            TickLoop(dataclasses.replace(loop.setup, shm_names=names), theirs, loop.notify_fd, None)
    finally:
        narrow.close()


def test_the_counters_segment_keeps_its_names_and_typed_writes_land_on_them(loop: TickLoop) -> None:
    from riderlive.realtime.counters import TickCounters
    from riderlive.realtime.pacing import LATENESS_BUCKETS

    assert COUNTERS[:4] == ("ticks", "overruns", "skipped", "lateness_sum")
    assert COUNTERS[TickCounters.phase_losses.index] == "phase_losses"
    assert COUNTERS[-len(LATENESS_BUCKETS) - 1 :] == tuple(
        f"lateness_bucket_{i}" for i in range(len(LATENESS_BUCKETS) + 1)
    )
    counter = loop.counter
    counter.ticks += 1
    counter.lateness_max = 0.002
    counter.set_saddle({"samples": 5, "stale": 2})
    counter.count_lateness(1)
    snapshot = loop.counters.snapshot()
    assert snapshot["ticks"] == 1 and snapshot["lateness_max"] == 0.002
    assert snapshot["saddle_samples"] == 5 and snapshot["saddle_stale"] == 2 and snapshot["lateness_bucket_1"] == 1
    with pytest.raises(KeyError):
        counter.set_saddle({"unknown": 1})
    counter.count_tick(2, 3, 0.001, 0.0015, 1)
    counter.count_tick(2, 3, 0.0005, 0.0004, 0)
    after = loop.counters.snapshot()
    assert (after["ticks"], after["overruns"], after["skipped"]) == (3, 2, 3)
    assert after["lateness_sum"] == pytest.approx(0.0015) and after["lateness_max"] == 0.002, "the max kept"
    assert after["step_max"] == 0.0015 and after["lateness_bucket_1"] == 2 and after["lateness_bucket_0"] == 1
