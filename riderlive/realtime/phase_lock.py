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
  analysed. The mean interval (the least-squares fit of every frame, :func:`fit_clock`, not
  the window's two ends) says how the producer's rate relates to the tick's:
  about a whole multiple ``m`` of the period (``m`` = 1 the same rate, ``m`` > 1 a
  divisor rate: every m-th tick takes a frame) gives harmonic ``k`` = 1; about
  ``period / k`` (a multiple rate, ``k`` frames per tick) gives harmonic ``k``. Any
  other rate has no fixed phase against the tick: no lock, nor for a phase that drifts
  more than ``max_drift`` (seconds per second, between the window's halves; a lock is
  kept up to ``keep_drift``). The arrival phase is the circular mean of
  ``k * t / period`` (turns), its spread the resultant length ``R`` (1: every frame at
  the same phase, about 1/sqrt(n) for a random stream); the expected arrival is the
  median phase around that mean (a few frames late by milliseconds pull the mean, not
  the median), moved on by the drift measured from step to step.
- **Margin.** The time after the expected arrival for the deadline whose waits (arrival
  to deadline) over the window have the least ``quantile``, at least ``margin``. A frame
  later than its deadline waits a whole span more, so with the default 0.998 (the worst
  wait of 256 frames; about one frame in 250 then misses its deadline) the margin is
  the arrival jitter's top: the floor for a steady producer, milliseconds on a busy
  machine, where that still beats a miss (:func:`best_margin`).
- **Own time.** ``R`` is measured against the tick's grid, and the receive stamps are the
  web process's: a frame that comes while it sends the tick's record is stamped when that
  ends, a fixed time after each deadline, so any stream shows some ``R`` (0.4-0.7 for a
  stalling 120 Hz producer into a 500 Hz tick). The frames must also keep their own time:
  the interquartile range of their residuals from :func:`fit_clock` (``spread``) at most
  ``max_spread`` (half) x ``period / k`` (``keep_spread``, 3/4, to stay locked).
- **Lock.** Locked when ``R >= lock_resultant`` and the spread fits, over at least
  ``min_samples`` frames at a rate that fits; let go (the deadlines keep the phase they
  have: *hold*) when ``R`` falls below ``unlock_resultant`` or the spread grows past
  ``keep_spread``, the rate stops fitting, the producer changes, or no frame came for
  ``gap`` seconds (the window is then emptied; the tick's driver leaves the input at
  about the same time, ``input.hold``); ``lost`` says why.
- **Slew.** While locked each step moves the deadlines by ``gain`` x the phase error,
  at most ``slew`` x period: consecutive deadlines stay between ``(1 - slew)`` and
  ``(1 + slew)`` periods apart, so the rate the bus, the physics' fixed step and the
  dead-man see is unchanged, only the phase moves (following a producer whose clock
  runs a few hundred ppm off moves the tick's mean rate by as much; ``keep_drift`` at most).

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
    """The margin is the one whose waits (arrival to deadline) over the window have the least
    of this quantile (``best_margin``), and at least ``margin``."""
    slew: float = 0.02
    """Fraction of a period the deadlines may move per tick, at most."""
    gain: float = 0.25
    """Fraction of the phase error corrected per tick (then bounded by ``slew``)."""
    window: int = 256
    """Receive times analysed (the newest)."""
    min_samples: int = 96
    """Frames seen before a lock (a random stream's resultant length is about 1/sqrt(n): 0.1)."""
    lock_resultant: float = 0.5
    unlock_resultant: float = 0.3
    max_spread: float = 0.5
    """The frames' lateness against their own steady clock (the interquartile range of the
    residuals of :func:`fit_clock`, a fraction of ``period / harmonic``) for a lock: a sanity
    check, ``R`` judges the phase (Gaussian jitter of IQR 0.25 span already gives ``R`` 0.5);
    a producer that stalls for longer than the span and catches up keeps no time of its own,
    whatever ``R`` the receive stamps show ..."""
    keep_spread: float = 0.75
    """... and to keep one."""
    rate_tolerance: float = 0.02
    """Relative difference of the mean interval from a whole multiple (or fraction) of the period."""
    max_drift: float = 0.001
    """Seconds per second the arrival phase may move for a lock (the producer's clock against
    ours, 1000 ppm) ..."""
    keep_drift: float = 0.003
    """... and to keep one (the estimate is noisy when the arrivals are): the most the lock
    changes the tick's mean rate by."""
    max_harmonic: int = 8
    """Up to this many frames per tick still have a phase (a faster producer: no lock)."""
    max_ratio: int = 8
    """Down to one frame every this many ticks still has a phase (a slower producer: no lock)."""
    gap: float = 0.25
    """No frame for this long (seconds, and at least ``gap_intervals`` intervals): the input
    stopped. A shorter stall on a busy machine keeps the lock (a paced producer resumes in
    phase); by default this is ``input.hold``, after which the tick eases to neutral anyway."""
    gap_intervals: float = 3.0
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
        if not (0.0 < self.max_spread <= self.keep_spread):
            raise ValueError("phase lock: 0 < max_spread <= keep_spread")


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
    """Mean time between frames at the last analysis."""
    resultant: float = 0.0
    spread: float = math.nan
    """The frames' lateness against their own clock at the last analysis (seconds; ``Analysis.spread``)."""
    arrival: float = math.nan
    """Expected arrival phase (in ``[0, period / harmonic)``) as of ``at``; NaN before the first analysis."""
    at: float = math.nan
    drift: float = 0.0
    """Seconds per second the arrival phase moves (measured at the last analysis); ``arrival``
    follows it from step to step."""
    margin: float = math.nan
    """Expected arrival to deadline wanted (the model's margin, or the jitter when larger)."""
    next_analysis: float = -math.inf
    slews: int = 0
    """Steps that moved the deadlines."""
    locks: int = 0
    losses: int = 0
    lost: str = ""
    """Why the last lock was let go: ``the input stopped``, ``no input drives``, ``another
    producer``, ``irregular`` (resultant length), ``another rate``, ``another harmonic``."""


def start(origin: float) -> State:
    """The state of a tick whose deadlines are at ``origin + n * period`` (engine seconds)."""
    return State(offset=origin)


def lead(model: Model, state: State) -> float:
    """Seconds from the expected arrival to the next deadline after it (NaN before an analysis)."""
    if math.isnan(state.arrival):
        return math.nan
    return (state.offset - state.arrival) % (model.period / state.harmonic)


class Analysis(NamedTuple):
    """What :func:`analyse` finds in a window of receive times."""

    harmonic: int
    interval: float
    fits: bool
    """The rate has a phase against the tick: a whole multiple or fraction of it (``drift`` aside)."""
    resultant: float
    spread: float
    """Interquartile range (seconds) of the receive times' residuals from :func:`fit_clock`: how
    well the frames keep their own time, whatever the tick does (``max_spread``)."""
    arrival: float
    at: float
    """The time ``arrival`` is the phase of (the window's mean receive time)."""
    margin: float
    drift: float
    """Seconds per second the arrival phase moved over the window (the rates' relative difference)."""


def analyse(model: Model, times: Sequence[float]) -> Analysis:
    """Rate, harmonic, resultant length, arrival phase and margin of ``times`` (at least 2)."""
    t = np.asarray(times, dtype=np.float64)
    period = model.period
    interval, residuals = fit_clock(t)
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
    rel = t - t[0]  # small numbers, exact to ns
    turns = np.mod(rel, span) / span
    z = np.exp(2j * math.pi * turns)
    half = len(t) // 2  # the phase's drift between the window's halves: the rates differ that much
    turned = complex(np.mean(z[half:])) * complex(np.mean(z[:half])).conjugate()
    drift = math.atan2(turned.imag, turned.real) / (2.0 * math.pi) * span
    drift /= max(float(np.mean(rel[half:]) - np.mean(rel[:half])), 1e-9)
    centre = float(np.mean(rel))
    turns -= drift * (rel - centre) / span  # every phase as of the window's mean time
    mean_z = complex(np.mean(np.exp(2j * math.pi * turns)))
    resultant = abs(mean_z)
    mean = math.atan2(mean_z.imag, mean_z.real) / (2.0 * math.pi)
    late = np.sort((np.mod(turns - mean + 0.5, 1.0) - 0.5) * span)  # seconds after the mean, in [-span/2, span/2)
    median = float(late[len(late) // 2])  # the expected arrival: the median (late outliers pull the mean)
    late -= median
    arrival = (float(t[0]) + mean * span + median) % span
    margin = best_margin(model, late, span)
    return Analysis(
        harmonic, interval, fits, resultant, spread(residuals), arrival, float(t[0]) + centre, margin, drift
    )


def fit_clock(t: np.ndarray) -> tuple[float, np.ndarray]:
    """The producer's own steady clock: ``(interval, residuals)``, the least-squares line of the
    receive times ``t`` (seconds, at least 2) against each frame's number, and each frame's
    distance from it (seconds).

    Not ``(t[-1] - t[0]) / (n - 1)``: that reads the rate off the two end frames alone, and
    a producer late by tens of milliseconds at one end (a busy host) then looks like another
    rate (a 120 Hz stream as 125 Hz, which fits a 500 Hz tick); the fit weighs every frame.
    Frames are numbered one after another (a producer that falls behind and catches up
    sends every frame); when the median gap is at least ``SKIP_GAP`` of that fit's interval
    (fewer than a quarter of the frames missing, and not a bursty stream, whose median gap
    is short), also by their gaps in median gaps (a producer that skips the frames it
    missed: a dropout is a gap of two), and the better fit (less :func:`spread`) wins."""
    rel = t - t[0]
    k = np.arange(len(t), dtype=np.float64)
    best = _line(k, rel)
    gaps = np.diff(rel)
    median = float(np.median(gaps)) if len(gaps) else 0.0
    if median > 0.0 and median >= SKIP_GAP * best[0]:
        skipped = _line(np.concatenate(([0.0], np.cumsum(np.maximum(1.0, np.rint(gaps / median))))), rel)
        if spread(skipped[1]) < spread(best[1]):
            best = skipped
    return best


SKIP_GAP = 0.75
"""See :func:`fit_clock`."""


def _line(number: np.ndarray, rel: np.ndarray) -> tuple[float, np.ndarray]:
    """Least-squares slope of ``rel`` against ``number``, and the residuals."""
    k = number - float(np.mean(number))
    interval = float(np.dot(k, rel) / max(float(np.dot(k, k)), 1e-12))
    return interval, rel - float(np.mean(rel)) - interval * k


def spread(residuals: np.ndarray) -> float:
    """The interquartile range of ``residuals`` (seconds): robust to a few very late frames."""
    q25, q75 = np.quantile(residuals, (0.25, 0.75))
    return float(q75 - q25)


def best_margin(model: Model, late: np.ndarray, span: float) -> float:
    """The time after the expected arrival for the deadline whose waits have the least ``quantile``.

    ``late``: sorted arrival times after the expected one (seconds, about within half a ``span``).
    A frame ``d`` after it waits ``margin - d`` for a deadline ``margin`` after it,
    or a ``span`` more when it came after it (then the next deadline takes it). Candidates
    are ``model.margin`` and the later half of the arrivals (up to half a span); the least
    of equally good ones wins."""
    n = len(late)
    top = np.clip(late[n // 2 :], model.margin, 0.5 * span)
    candidates = np.unique(np.concatenate(([model.margin], top)))
    waits = candidates[:, None] - late[None, :]
    waits += np.where(waits < 0.0, span, 0.0)
    k = min(n - 1, math.ceil(model.quantile * n) - 1)
    return float(candidates[int(np.argmin(np.partition(waits, k, axis=1)[:, k]))])


def step(model: Model, state: State, now: float, producer: int, arrivals: Sequence[float]) -> State:
    """One tick at engine time ``now`` (its deadline): ``arrivals`` are the receive times of the
    frames of ``producer`` (the driving producer's id, -1 for none) the tick just took.

    Returns the new state; ``shift`` says how far to move the deadlines from the next on
    (``|shift| <= slew * period``; 0 when not locked)."""
    if producer != state.producer:
        state = _let_go(state, "another producer" if producer >= 0 else "no input drives")
        state = state._replace(producer=producer, times=())
    if arrivals and producer >= 0:
        fresh = tuple(t for t in arrivals if math.isfinite(t))
        state = state._replace(times=(state.times + fresh)[-model.window :])
    times = state.times
    if times:
        interval = state.interval if state.interval > 0.0 else model.period
        if now - times[-1] > max(model.gap, model.gap_intervals * max(interval, model.period)):
            state = _let_go(state, "the input stopped")._replace(times=())
    if now >= state.next_analysis and len(state.times) >= model.min_samples:
        state = _analysed(model, state, now)
    if state.drift != 0.0 and now > state.at:
        state = state._replace(arrival=state.arrival + state.drift * (now - state.at), at=now)
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
    span = model.period / a.harmonic
    threshold, drift, widest = (
        (model.unlock_resultant, model.keep_drift, model.keep_spread)
        if state.locked
        else (model.lock_resultant, model.max_drift, model.max_spread)
    )
    regular = a.resultant >= threshold and a.spread <= widest * span
    locked = a.fits and abs(a.drift) <= drift and regular
    if state.locked and (not locked or a.harmonic != state.harmonic):
        why = "irregular" if not regular else "another rate" if a.harmonic == state.harmonic else ""
        state = _let_go(state, why or "another harmonic")
        locked = (
            a.fits
            and abs(a.drift) <= model.max_drift
            and a.resultant >= model.lock_resultant
            and a.spread <= model.max_spread * span
        )
    return state._replace(
        locked=locked,
        locks=state.locks + (locked and not state.locked),
        harmonic=a.harmonic,
        interval=a.interval,
        resultant=a.resultant,
        spread=a.spread,
        arrival=a.arrival,
        at=a.at,
        drift=a.drift,
        margin=a.margin,
        next_analysis=now + model.analysis_interval,
    )


def _let_go(state: State, why: str) -> State:
    """Unlocked; the deadlines keep their phase."""
    if not state.locked:
        return state
    return state._replace(locked=False, losses=state.losses + 1, lost=why)
