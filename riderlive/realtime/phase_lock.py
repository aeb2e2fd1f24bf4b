"""Phase lock of the tick to its live input: deadlines a small margin after the frames arrive.

A producer streaming at the tick's rate is not in phase with the tick: a frame waits
for the next deadline, uniformly 0..1 period (at 120 Hz, p99 8.25 ms of the 9.33 ms
ingest-to-send budget). This unit learns the phase at which the driving producer's
frames arrive (their receive times, engine seconds) and moves the tick's deadlines,
slowly, so that each falls ``margin`` after the expected arrival.

Pure: :func:`step` takes the :class:`State` and returns a new one; it reads no clock.
The tick (``realtime/tick.py``) calls it once per tick after the tick's output is out,
with the receive times of the horse frames it took from the driving producer, and
moves its :class:`~riderlive.realtime.pacing.DeadlineClock` by ``state.shift``.

Times are engine seconds; phases are seconds in ``[0, period / harmonic)``.

- **Phase.** Every ``analysis_interval`` seconds the last ``window`` receive times are
  analysed. The median interval says how the producer's rate relates to the tick's:
  about a whole multiple ``m`` of the period (``m`` = 1 the same rate, ``m`` > 1 a
  divisor rate: every m-th tick takes a frame) gives harmonic ``k`` = 1; about
  ``period / k`` (a multiple rate, ``k`` frames per tick) gives harmonic ``k``. Any
  other rate has no fixed phase against the tick: no lock. The arrival phase is the
  circular mean of ``k * t / period`` (turns), its spread the resultant length ``R``
  (1: every frame at the same phase, 0: uniform).
- **Margin.** ``max(margin, the quantile-th quantile of the arrivals' lateness after
  that mean)``: with the default 0.998 over 256 frames (the largest or the second), about one frame
  in 500 arrives after the deadline meant for it and waits one more period (which is
  still less than a period after it arrived), so the p99 of the wait is about the margin.
- **Lock.** Locked when ``R >= lock_resultant`` over at least ``min_samples`` frames at a
  rate that fits; let go (the deadlines keep the phase they have: *hold*) when ``R``
  falls below ``unlock_resultant``, the rate stops fitting, the producer changes, or no
  frame came for ``gap_intervals`` intervals (the window is then emptied).
- **Slew.** While locked each step moves the deadlines by ``gain`` x the phase error,
  at most ``slew`` x period: consecutive deadlines stay between ``(1 - slew)`` and
  ``(1 + slew)`` periods apart, so the rate the bus, the physics' fixed step and the
  dead-man see is unchanged, only the phase moves (following a producer whose clock
  runs a fraction of a per mille off moves the tick's mean rate by as much).

Without input (``producer`` -1, or no frames) nothing moves: the deadlines are
``start + n * period``, as without the lock.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np


@dataclass(frozen=True)
class Model:
    """Static parameters (seconds unless said)."""

    period: float
    """The tick's period."""
    margin: float = 0.0003
    """The least time from the expected arrival to the deadline."""
    quantile: float = 0.998
    """Of the arrivals' lateness after their mean phase: the margin when larger."""
    slew: float = 0.02
    """Fraction of a period the deadlines may move per tick, at most."""
    gain: float = 0.25
    """Fraction of the phase error corrected per tick (then bounded by ``slew``)."""
    window: int = 256
    """Receive times analysed (the newest)."""
    min_samples: int = 48
    """Frames seen before a lock."""
    lock_resultant: float = 0.8
    unlock_resultant: float = 0.6
    rate_tolerance: float = 0.02
    """Relative difference of the median interval from a whole multiple (or fraction) of the period."""
    max_harmonic: int = 8
    """Up to this many frames per tick still have a phase (a faster producer: no lock)."""
    max_ratio: int = 8
    """Down to one frame every this many ticks still has a phase (a slower producer: no lock)."""
    gap_intervals: float = 4.0
    """No frame for this many intervals (at least periods): the input stopped."""
    analysis_interval: float = 0.05
    deadband: float = 2e-6
    """A correction smaller than this is not made (not counted as a slew)."""

    def __post_init__(self) -> None:
        if not (self.period > 0.0 and 0.0 <= self.margin < self.period and 0.0 < self.slew <= 0.1):
            raise ValueError("phase lock: period > 0, 0 <= margin < period, 0 < slew <= 0.1")
        if not (0.0 < self.unlock_resultant <= self.lock_resultant < 1.0 and 0.5 <= self.quantile < 1.0):
            raise ValueError("phase lock: 0 < unlock_resultant <= lock_resultant < 1, 0.5 <= quantile < 1")
        if not (2 <= self.min_samples <= self.window):
            raise ValueError("phase lock: 2 <= min_samples <= window")


class State(NamedTuple):
    """Everything that changes; a new value per step."""

    offset: float = 0.0
    """Phase of the deadlines: deadline n is at ``offset + n * period`` (engine seconds, unwrapped)."""
    shift: float = 0.0
    """What the last step moved the deadlines by (added to ``offset``)."""
    producer: int = -1
    """The producer whose frames are in ``times``."""
    times: tuple[float, ...] = ()
    """Receive times of its frames, oldest first (at most ``window``)."""
    locked: bool = False
    harmonic: int = 1
    interval: float = math.nan
    """Median time between frames at the last analysis."""
    resultant: float = 0.0
    arrival: float = math.nan
    """Expected arrival phase (in ``[0, period / harmonic)``); NaN before the first analysis."""
    margin: float = math.nan
    """Expected arrival to deadline wanted (the model's margin, or the jitter when larger)."""
    next_analysis: float = -math.inf
    slews: int = 0
    """Steps that moved the deadlines."""
    locks: int = 0
    losses: int = 0


def start(origin: float) -> State:
    """The state of a tick whose deadlines are at ``origin + n * period`` (engine seconds)."""
    return State(offset=origin)


def lead(model: Model, state: State) -> float:
    """Seconds from the expected arrival to the next deadline after it (NaN before an analysis)."""
    if math.isnan(state.arrival):
        return math.nan
    return (state.offset - state.arrival) % (model.period / state.harmonic)


class Analysis(NamedTuple):
    harmonic: int
    interval: float
    fits: bool
    resultant: float
    arrival: float
    margin: float


def analyse(model: Model, times: Sequence[float]) -> Analysis:
    """Rate, harmonic, resultant length, arrival phase and margin of ``times`` (at least 2)."""
    t = np.asarray(times, dtype=np.float64)
    period = model.period
    gaps = np.sort(np.diff(t))
    interval = float(gaps[len(gaps) // 2])  # the median (the upper one of an even count)
    harmonic, fits = 1, False
    if interval > 0.0:
        ratio = interval / period
        if ratio >= 1.0 - model.rate_tolerance:
            m = max(1, round(ratio))
            fits = m <= model.max_ratio and abs(ratio - m) <= model.rate_tolerance * m
        else:
            harmonic = round(1.0 / ratio)
            fits = 2 <= harmonic <= model.max_harmonic and abs(ratio * harmonic - 1.0) <= model.rate_tolerance
            harmonic = min(max(harmonic, 1), model.max_harmonic)
    span = period / harmonic
    turns = np.mod(t - t[0], span) / span  # t[0]: small numbers, exact to ns
    angle = 2.0 * math.pi * turns
    c, s = float(np.mean(np.cos(angle))), float(np.mean(np.sin(angle)))
    resultant = math.hypot(c, s)
    mean = math.atan2(s, c) / (2.0 * math.pi)
    late = (np.mod(turns - mean + 0.5, 1.0) - 0.5) * span  # seconds after the mean phase, in [-span/2, span/2)
    late.sort()
    jitter = float(late[min(len(late) - 1, math.ceil(model.quantile * len(late)) - 1)])  # nearest rank
    arrival = (float(t[0]) + mean * span) % span
    margin = min(max(model.margin, jitter), 0.5 * span)
    return Analysis(harmonic, interval, fits, resultant, arrival, margin)


def step(model: Model, state: State, now: float, producer: int, arrivals: Sequence[float]) -> State:
    """One tick at engine time ``now`` (its deadline): ``arrivals`` are the receive times of the
    frames of ``producer`` (the driving producer's id, -1 for none) the tick just took.

    Returns the new state; ``shift`` says how far to move the deadlines from the next on
    (``|shift| <= slew * period``; 0 when not locked)."""
    if producer != state.producer:
        state = _let_go(state)._replace(producer=producer, times=())
    if arrivals and producer >= 0:
        fresh = tuple(t for t in arrivals if math.isfinite(t))
        state = state._replace(times=(state.times + fresh)[-model.window :])
    times = state.times
    if times:
        interval = state.interval if state.interval > 0.0 else model.period
        if now - times[-1] > model.gap_intervals * max(interval, model.period):
            state = _let_go(state)._replace(times=())
    if now >= state.next_analysis and len(state.times) >= model.min_samples:
        state = _analysed(model, state, now)
    if not state.locked:
        return state._replace(shift=0.0)
    span = model.period / state.harmonic
    target = state.arrival + state.margin
    error = (target - state.offset + 0.5 * span) % span - 0.5 * span
    bound = model.slew * model.period
    shift = min(max(model.gain * error, -bound), bound)
    if abs(shift) < model.deadband:
        return state._replace(shift=0.0)
    return state._replace(offset=state.offset + shift, shift=shift, slews=state.slews + 1)


def _analysed(model: Model, state: State, now: float) -> State:
    a = analyse(model, state.times)
    threshold = model.unlock_resultant if state.locked else model.lock_resultant
    locked = a.fits and a.resultant >= threshold
    if state.locked and (not locked or a.harmonic != state.harmonic):
        state = _let_go(state)
        locked = a.fits and a.resultant >= model.lock_resultant
    return state._replace(
        locked=locked,
        locks=state.locks + (locked and not state.locked),
        harmonic=a.harmonic,
        interval=a.interval,
        resultant=a.resultant,
        arrival=a.arrival,
        margin=a.margin,
        next_analysis=now + model.analysis_interval,
    )


def _let_go(state: State) -> State:
    """Unlocked; the deadlines keep their phase."""
    if not state.locked:
        return state
    return state._replace(locked=False, losses=state.losses + 1)
