"""``devices/shared.py``: a slot written by one process is never seen half written by another."""

from __future__ import annotations

import multiprocessing as mp
import time
from multiprocessing.synchronize import Event

from riderlive.devices.shared import Slot, SlotBlock, Slots


class Beats(SlotBlock):
    """Three slots of one segment, as the board declares its own (by attribute)."""

    before = Slot(float, "nobody")
    beat = Slot(float, "the writer")
    after = Slot(float, "nobody")

    def __init__(self, name: str | None = None) -> None:
        self.segment = Slots(self.slot_names(), name)
        self.values = self.segment.values


def write_beats(name: str, ready: Event, done: Event) -> None:
    """Write 1, 2, 3... into ``beat`` as fast as it can until ``done`` (a guardian's beat, sped up)."""
    slots = Beats(name)
    ready.set()
    n = 0.0
    while not done.is_set():
        for _ in range(1000):
            n += 1.0
            slots.beat = n
    slots.segment.close()


def test_a_slot_written_in_a_loop_is_never_read_as_zero_or_going_back() -> None:
    """The soak's false guardian hang ("has not beaten for 23425072 ms": a beat read as 0.0):
    ``struct.pack_into`` zero-fills before it packs, and a reader in another process saw 0.0
    in ~5 % of its reads. Every read here is a value the writer wrote: > 0, never smaller
    than the one before. (The old code: thousands of zeros a second.)"""
    slots = Beats()
    context = mp.get_context("spawn")
    ready, done = context.Event(), context.Event()
    writer = context.Process(target=write_beats, args=(slots.segment.name, ready, done))
    writer.start()
    try:
        assert ready.wait(120.0), "the writer did not start"
        while slots.beat == 0.0:  # its first write
            pass
        last, reads, zeros, backwards = 0.0, 0, 0, 0
        end = time.perf_counter() + 1.5
        while time.perf_counter() < end:
            for _ in range(1000):
                value = slots.beat
                zeros += value == 0.0
                backwards += value < last
                last = max(last, value)
                reads += 1
        assert slots.before == 0.0 and slots.after == 0.0
    finally:
        done.set()
        writer.join(30.0)
        slots.segment.close()
    assert reads > 10_000 and last > 10_000.0  # both really ran at once
    assert (zeros, backwards) == (0, 0), f"{zeros} zeros and {backwards} values going back in {reads} reads"


def test_values_round_trip_and_close_after_use() -> None:
    slots = Beats()
    other = Beats(slots.segment.name)
    slots.beat, slots.after = 12345.678, 7  # an int is stored as a float
    assert other.beat == 12345.678 and other.after == 7.0 and isinstance(other.after, float)
    other.segment.close()
    slots.segment.close()
