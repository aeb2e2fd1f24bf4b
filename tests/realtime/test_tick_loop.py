"""The tick loop in-process: a failing or non-finite step repeats the last good frame."""

from __future__ import annotations

import math
import multiprocessing
import os
import time

import pytest

from riderlive.realtime import layout as L
from riderlive.realtime.core import Driver, TickResult, Timing
from riderlive.realtime.shm import SharedBlob, SharedCounters, SharedRing
from riderlive.realtime.tick import TickLoop, TickSetup
from riderlive.rules import RuleParams
from riderlive.rules.animator import AnimatorLayer


@pytest.fixture
def loop():
    shared = [SharedRing(64, L.INPUT_WIDTH), SharedRing(64, L.OUTPUT_WIDTH), SharedCounters(L.COUNTERS), SharedBlob()]
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
    values, index = loop.counters.values, loop.counters.index
    good = loop._step(0.01, values, index)
    assert all(math.isfinite(v) for v in good.rider)

    def broken(now: float) -> TickResult:
        raise ZeroDivisionError("boom")

    loop.core.step = broken  # type: ignore[method-assign]
    assert loop._step(0.02, values, index) is good
    assert values[index["step_errors"]] == 1
    assert "boom" in loop.events[-1]


def test_a_non_finite_rider_never_leaves_the_tick(loop: TickLoop) -> None:
    values, index = loop.counters.values, loop.counters.index
    nan = TickResult(Driver.INPUT, 0.0, 1, [0.0] * L.N_HORSE, [math.nan] * L.N_RIDER)
    loop.core.step = lambda now: nan  # type: ignore[method-assign]
    first = loop._step(0.0, values, index)
    assert first.driver is Driver.NEUTRAL and first.rider == loop.core.neutral_rider
    assert values[index["nonfinite_outputs"]] == 1
