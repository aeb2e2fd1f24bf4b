"""The tick's intake (``realtime/intake.py``) over a real shared ring and a real core: what it
takes, counts and hands the phase lock, and a rebased record reaching the clock mapping."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from riderlive.channels import HORSE_NAMES
from riderlive.horse import ProceduralHorse
from riderlive.realtime import layout as L
from riderlive.realtime.core import TickCore, Timing
from riderlive.realtime.counters import COUNTERS, TickCounters
from riderlive.realtime.intake import Intake
from riderlive.realtime.latency import LatencyHistogram
from riderlive.realtime.shm import SharedRing
from riderlive.rules import RiderModel

ZERO = [0.0] * len(HORSE_NAMES)


@pytest.fixture
def ring() -> Iterator[SharedRing]:
    ring = SharedRing(64, L.INPUT_WIDTH)
    yield ring
    ring.close()


def intake(ring: SharedRing) -> Intake:
    core = TickCore(RiderModel(scale=25.0), Timing(delay=0.0, hold=1.0), ProceduralHorse())
    return Intake(ring, core, TickCounters(np.zeros(len(COUNTERS))), LatencyHistogram(), 0.01)


def test_it_takes_new_records_counts_the_refused_and_keeps_the_driving_producers_arrivals(ring: SharedRing) -> None:
    taken = intake(ring)
    for producer, t, rx in [(1, 10.0, 0.50), (1, 10.01, 0.51), (1, 10.005, 0.52), (2, 3.0, 0.53), (2, 3.01, 0.54)]:
        ring.write(L.InputRecord(producer, t, rx, ZERO).row())
    ring.write(L.InputRecord(2, 3.02, 0.55, [0.0] * 6, L.InputKind.SADDLE).row())
    assert taken.read(0.60, 100.0, None) == 0.55
    counter = taken.counter
    # the third frame is not after the producer's last (refused); the saddle sample switches
    # nothing (same producer) and is no horse arrival for the phase lock
    assert (counter.input_frames, counter.input_out_of_order) == (5, 1)
    assert taken.arrivals == [0.53, 0.54]  # producer 1's arrivals dropped at the switch to 2
    assert taken.ingest_to_tick.count == 1 and taken.ingest_to_tick.values.max() > 0.0
    assert taken.read(0.61, 100.01, None) == -1.0 and taken.arrivals == []  # nothing new


def test_a_rebased_record_starts_the_clock_rates_baseline_over(ring: SharedRing) -> None:
    taken = intake(ring)
    for k in range(300):  # 2.5 s at 120 Hz: the rate's windows fill
        ring.write(L.InputRecord(1, k / 120, k / 120 + 0.001, ZERO).row())
        taken.read(k / 120 + 0.002, 100.0, None)
    clock = taken.core.resampler.clock
    assert len(clock.windows) >= 9 and clock.anchor is not None
    rate = clock.rate
    ring.write(L.InputRecord(1, 300 / 120, 300 / 120 + 0.001, ZERO, rebased=False).row())
    taken.read(2.51, 100.0, None)
    assert len(clock.windows) >= 9
    ring.write(L.InputRecord(1, 301 / 120, 301 / 120 + 0.001, ZERO, rebased=True).row())
    taken.read(2.52, 100.0, None)
    assert len(clock.windows) == 0 and clock.least is not None and clock.least[0] == 301 / 120  # from it on
    assert clock.rate == rate  # the rate in use is kept
