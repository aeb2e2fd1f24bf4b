"""The tick's counters in shared memory: typed slots, written by the tick process only.

:class:`TickCounters` declares every counter once (name, type, meaning); the web process
makes the segment from :data:`COUNTERS` (the same names, in the same order) and reads it
by name (``SharedCounters.snapshot``: ``/metrics``, ``/api/latency``, the status). Each
slot is one aligned float64 store: a reader sees the old or the new value, never a mix.
Times are seconds.
"""

from __future__ import annotations

from collections.abc import Mapping

from riderlive.devices.shared import Slot, SlotBlock
from riderlive.realtime.pacing import LATENESS_BUCKETS
from riderlive.realtime.saddle_input import COUNTERS as SADDLE_COUNTERS
from riderlive.realtime.shm import FloatArray

TICK = "the tick process"


class TickCounters(SlotBlock):
    """The tick's counters, by attribute, over a :class:`~riderlive.realtime.shm.SharedCounters`'s values."""

    ticks = Slot(int, TICK, "ticks run")
    overruns = Slot(int, TICK, "ticks that ended after the next deadline (DeadlineClock.overruns)")
    skipped = Slot(int, TICK, "deadlines passed over after an overrun")
    lateness_sum = Slot(float, TICK, "s, the sum of every tick's lateness")
    lateness_max = Slot(float, TICK, "s, the latest wake after a deadline")
    step_max = Slot(float, TICK, "s, the longest deadline-to-done")
    input_frames = Slot(int, TICK, "input records taken")
    input_lapped = Slot(int, TICK, "input records the web process overwrote before the tick read them")
    input_out_of_order = Slot(int, TICK, "input records refused: not after the producer's last")
    input_pickup_waits = Slot(int, TICK, "ticks that waited at their pickup for a frame received before the deadline")
    step_errors = Slot(int, TICK, "steps that raised (the last good frame repeated)")
    nonfinite_outputs = Slot(int, TICK, "steps that gave a non-finite rider (the last good frame repeated)")
    physics_errors = Slot(int, TICK, "tail physics restarts after a failed step")
    physics_skipped_steps = Slot(int, TICK, "tail physics steps skipped after long stalls")
    state_resets = Slot(int, TICK, "rules state resets (TickCore.resets)")
    outputs_clamped = Slot(int, TICK, "rider values clamped to the ranges (TickCore.clamped)")
    hands_full_reach = Slot(int, TICK, "ticks the hands were at full reach (TickCore.full_reach)")
    realtime = Slot(float, TICK, "1 while the tick runs at SCHED_FIFO, else 0")
    alive = Slot(float, TICK, "1 while the loop runs, 0 once it returned")
    saddle_samples = Slot(int, TICK, "saddle samples taken (saddle input)")
    saddle_missing = Slot(int, TICK, "saddle samples with an axis missing")
    saddle_empty = Slot(int, TICK, "saddle samples with no axis")
    saddle_gaps = Slot(int, TICK, "gaps in the saddle stream")
    saddle_glitches = Slot(int, TICK, "saddle samples rejected as glitches")
    saddle_rebases = Slot(int, TICK, "saddle estimator rebases")
    saddle_locks = Slot(int, TICK, "saddle gait locks taken")
    saddle_losses = Slot(int, TICK, "saddle gait locks lost")
    saddle_stale = Slot(int, TICK, "episodes of a stale saddle stream")
    input_clock_rate = Slot(float, TICK, "the horse stream's producer clock rate (resample.ClockMap; 0: no tick yet)")
    saddle_clock_rate = Slot(float, TICK, "the saddle stream's producer clock rate in use (the same ClockMap)")
    phase_locked = Slot(float, TICK, "1 while the deadlines are phase locked to the producer")
    phase_lead = Slot(float, TICK, "s, the deadline's lead over the expected arrival (-1: none)")
    phase_margin = Slot(float, TICK, "s, the margin kept (-1: none)")
    phase_resultant = Slot(float, TICK, "the arrival phases' resultant length (0-1)")
    phase_slews = Slot(int, TICK, "deadline slews")
    phase_locks = Slot(int, TICK, "phase locks taken")
    phase_losses = Slot(int, TICK, "phase locks lost")

    def __init__(self, values: FloatArray) -> None:
        """``values``: the segment's float64 array (``SharedCounters.values``, made from :data:`COUNTERS`)."""
        self.values = values
        self.bucket0 = len(self.slots())
        """Index of ``lateness_bucket_0`` (the lateness histogram's bins follow the slots)."""

    def count_lateness(self, bucket: int) -> None:
        """One tick in lateness bucket ``bucket`` (``pacing.bucket_of``)."""
        self.values[self.bucket0 + bucket] += 1

    def count_tick(self, overruns: int, skipped: int, lateness: float, step: float, bucket: int) -> None:
        """One tick's pacing counters: ``ticks``, ``overruns`` and ``skipped`` (the clock's totals),
        ``lateness_sum``/``lateness_max`` and ``step_max`` (s), lateness bucket ``bucket``. The
        slots' indices straight (the tick's hottest bookkeeping: half the cost of one attribute each)."""
        v = self.values
        v[_TICKS] += 1
        v[_OVERRUNS] = overruns
        v[_SKIPPED] = skipped
        v[_LATENESS_SUM] += lateness
        v[_LATENESS_MAX] = max(v[_LATENESS_MAX], lateness)
        v[_STEP_MAX] = max(v[_STEP_MAX], step)
        v[self.bucket0 + bucket] += 1

    def set_saddle(self, counts: Mapping[str, int]) -> None:
        """The saddle estimator's counters (``SaddleInput.counters``: :data:`SADDLE_COUNTERS` and ``stale``)."""
        for name, count in counts.items():
            _SADDLE_SLOTS[name].__set__(self, count)


_TICKS, _OVERRUNS, _SKIPPED = TickCounters.ticks.index, TickCounters.overruns.index, TickCounters.skipped.index
_LATENESS_SUM, _LATENESS_MAX = TickCounters.lateness_sum.index, TickCounters.lateness_max.index
_STEP_MAX = TickCounters.step_max.index
_SADDLE_SLOTS: dict[str, Slot[int]] = {n: TickCounters.slot(f"saddle_{n}") for n in (*SADDLE_COUNTERS, "stale")}
COUNTERS: tuple[str, ...] = (
    *TickCounters.slot_names(),
    *(f"lateness_bucket_{i}" for i in range(len(LATENESS_BUCKETS) + 1)),
)
"""The segment's slot names, in order: the typed counters, then the lateness histogram's bins."""
