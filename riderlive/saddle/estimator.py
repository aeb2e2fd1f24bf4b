"""The saddle-only estimator: saddle samples in, gait, stride frequency, phase and lock out.

Model / State / step, no clocks: :func:`step` takes one sample (its time in s and the
six ``channels.SADDLE`` values, NaN for a missing axis) and returns the next
:class:`State`; nothing else changes. The tick can step it once per received sample
and read :func:`riderlive.saddle.rebuild.horse_frame` at its own time; what it publishes is
:func:`riderlive.saddle.estimate.estimate` of the state.

Per sample (cheap): validation, glitch and re-zero handling, a light smoothing of the
pose, and one history row at most every ``resolution`` s. Every ``analysis_period``
of stream time, :func:`riderlive.saddle.analysis.analyse` fits the history, and the
result steers a numerically controlled oscillator (the stride phase) like a
phase-locked loop: the phase stays continuous, its rate absorbs half the measured
error per analysis. ``docs/saddle.md`` has the method, the states and the fallbacks.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from riderlive.horse.gaits import Gait
from riderlive.saddle.analysis import Fit, analyse
from riderlive.saddle.baseline import Drift, baseline
from riderlive.saddle.pose import SaddlePoint
from riderlive.saddle.templates import Template, templates
from riderlive.saddle.track import Ease, Track

FloatArray = npt.NDArray[np.float64]
CHANNELS = 6
_NAN6 = (math.nan,) * CHANNELS
_ZERO6 = (0.0,) * CHANNELS


class Lock(enum.Enum):
    """What the estimator knows: published as the lock state."""

    NO_SIGNAL = "no_signal"  # no usable stream: nothing yet, or too sparse (gaps)
    STILL = "still"  # a steady stream without periodic motion (a halt, a constant stream)
    SEARCHING = "searching"  # moving, but no gait fits (a transition, a jump, noise)
    LOCKED = "locked"  # a gait, its stride frequency and phase


@dataclass(frozen=True)
class Model:
    """Static parameters (seconds, metres, degrees); ``docs/saddle.md`` explains each."""

    point: SaddlePoint = field(default_factory=SaddlePoint)
    analysis_period: float = 0.1  # between analyses while locked and sure ...
    search_period: float = 0.05  # ... and otherwise
    history: float = 3.0
    resolution: float = 0.005
    max_interval: float = 0.2  # a longer wait between samples is a gap
    stale: float = 1.0  # a gap this long drops the history
    continuous: float = 0.5  # the stream must run without gaps this long before its pose is used
    hold: float = 0.5  # the estimate runs on this long after the last sample, then eases out
    ease: float = 0.25  # s: hooves and pose ease in and out, gaits blend, over this long at most ...
    ease_strides: float = 0.2  # ... or over this many strides of the locked gait, if shorter
    lock_score: float = 0.85
    keep_score: float = 0.7
    confirm_phase: float = 0.08  # strides: two analyses agreeing this well confirm a lock
    misses: int = 3  # analyses without a fit before a lock is let go
    pll_gain: float = 0.5
    frequency_gain: float = 0.5
    smoothing: float = 0.004  # time constant of the pose's smoothing (s): noise off, little delay
    limits: tuple[float, ...] = (5.0, 5.0, 5.0, 360.0, 360.0, 360.0)  # beyond: the axis is missing
    glitch_distance: float = 0.3  # m (and x 100 deg): a sample that far off the last ...
    glitch_speed: float = 3.0  # ... plus this many m/s (x 100 deg/s) of the gap, is a glitch
    rebase_samples: int = 3  # ... unless that many samples in a row stay there: a re-zero
    smooth_residual: float = 0.5  # lag-1 autocorrelation above which unexplained motion is motion, not noise
    level_time: float = 20.0  # pitch and roll keep their level; it follows the mean this slowly
    window_strides: float = 1.25  # the stride fit's window
    stay: float = 0.01  # score bonus of the locked gait (hysteresis between look-alike gaits)
    beat_beats: float = 1.6  # the beat fit's window, in beats of the last beat found ...
    beat_window: tuple[float, float] = (0.7, 1.2)  # ... within these seconds
    min_rate: float = 8.0  # samples per second a window needs

    def __post_init__(self) -> None:
        object.__setattr__(self, "_templates", templates(self.point))

    def ease_time(self, stride_hz: float) -> float:
        """Seconds the hooves take to ease in or out, or to blend gaits, at ``stride_hz``."""
        return min(self.ease, self.ease_strides / stride_hz) if stride_hz > 0.0 else self.ease

    @property
    def templates(self) -> dict[Gait, Template]:
        found: dict[Gait, Template] = self._templates  # type: ignore[attr-defined]
        return found


@dataclass(frozen=True, slots=True)
class Counters:
    """Everything odd the estimator saw, counted (published with the estimate)."""

    empty: int = 0  # samples with no usable axis, a non-finite time, or a time not after the last
    gaps: int = 0  # waits longer than max_interval between samples
    glitches: int = 0  # samples dropped as a jump (metres or tens of degrees off)
    rebases: int = 0  # jumps that stayed: the pose re-zeroed, absorbed into an offset
    analyses: int = 0
    locks: int = 0  # times a lock was (re)gained or moved to another gait or phase
    losses: int = 0  # times a lock was let go


@dataclass(frozen=True, slots=True)
class Tracking:
    """What changes at the analyses (and on rare events): history, fit, lock, oscillator, weights."""

    times: FloatArray = field(default_factory=lambda: np.empty(0))
    values: FloatArray = field(default_factory=lambda: np.empty((0, CHANNELS)))
    fit: Fit | None = None
    drift: Drift | None = None  # the baseline of translations and yaw (a line per channel)
    level: tuple[float, ...] | None = None  # pitch and roll level (slow mean)
    levels: int = 0  # lines that went into the level
    lock: Lock = Lock.NO_SIGNAL
    track: Track | None = None
    previous: Track | None = None  # the track a switch blends from
    switched: float = -math.inf
    candidate: Track | None = None
    missed: int = 0
    hooves: Ease = field(default_factory=Ease)  # weight of the gait's hooves (1 when locked)
    pose: Ease = field(default_factory=Ease)  # weight of the measured pose (0 when it is noise or gone)
    counters: Counters = Counters()


class State(NamedTuple):
    """Everything that changes; a new value per step (arrays inside are never modified).

    The fields a sample touches are here; the rest lives in :class:`Tracking`, which
    changes only at an analysis or on a rare event (a gap, a glitch).
    """

    t: float = -math.inf  # last accepted sample (s)
    last: tuple[float, ...] = _NAN6  # last accepted values (offset removed)
    smooth: tuple[float, ...] = _NAN6  # smoothed pose (for the rebuilt frame)
    offset: tuple[float, ...] = _ZERO6  # subtracted from every sample (re-zero steps)
    suspect: tuple[tuple[float, ...], ...] = ()  # glitch candidates in a row
    since: float = -math.inf  # start of the current run without gaps
    rows: tuple[tuple[float, ...], ...] = ()  # history rows not yet in the arrays
    next_row: float = -math.inf
    next_analysis: float = -math.inf
    samples: int = 0
    missing: int = 0  # samples with at least one axis missing (NaN or inf)
    tracking: Tracking = Tracking()

    @property
    def lock(self) -> Lock:
        return self.tracking.lock


def _counted(state: State, **changes: int) -> State:
    counters = state.tracking.counters
    more = {name: getattr(counters, name) + n for name, n in changes.items()}
    return state._replace(tracking=replace(state.tracking, counters=replace(counters, **more)))


def _far(model: Model, a: tuple[float, ...], b: tuple[float, ...], dt: float) -> bool:
    """Whether ``b`` is further from ``a`` than a saddle moves in ``dt`` (NaN axes ignored)."""
    limit = model.glitch_distance + model.glitch_speed * dt
    for i in range(CHANNELS):
        d = abs(b[i] - a[i])
        if not math.isnan(d) and d > (limit if i < 3 else 100.0 * limit):
            return True
    return False


def step(model: Model, state: State, t: float, values: Sequence[float]) -> State:
    """The state after one sample at time ``t`` (s) of the six saddle values (m, deg).

    An axis that is NaN, infinite or beyond ``model.limits`` counts as missing; a
    sample with no usable axis, the wrong length, or a time not after the last is
    counted (``empty``) and otherwise ignored.
    """
    t = float(t)
    dt = t - state.t
    if len(values) != CHANNELS or not (dt > 0.0 and t - t == 0.0):
        return _counted(state._replace(samples=state.samples + 1), empty=1)
    offset = state.offset
    sample: list[float] = []
    missing = False
    for v, o, limit in zip(values, offset, model.limits, strict=True):
        x = float(v)
        if -limit <= x <= limit:  # False for NaN too
            sample.append(x - o)
        else:
            sample.append(math.nan)
            missing = True
    if missing and all(math.isnan(x) for x in sample):
        return _counted(state._replace(samples=state.samples + 1), empty=1)
    fresh = state.t == -math.inf
    if not fresh and _far(model, state.last, tuple(sample), dt):
        state, sample_or_none = _glitch(model, state, tuple(sample), dt)
        if sample_or_none is None:
            return state._replace(samples=state.samples + 1, missing=state.missing + missing)
        sample, offset = list(sample_or_none), state.offset
    gap = not fresh and dt > model.max_interval
    a = 1.0 - math.exp(-dt / model.smoothing) if not fresh and not gap else 1.0
    last, smooth = list(state.last), list(state.smooth)
    for i, x in enumerate(sample):
        if not math.isnan(x):
            last[i] = x
            p = smooth[i]
            smooth[i] = x if math.isnan(p) else p + a * (x - p)
    rows, next_row = state.rows, state.next_row
    if t >= next_row:
        rows, next_row = (*rows, (t, *sample)), t + model.resolution
    state = State(
        t,
        tuple(last),
        tuple(smooth),
        offset,
        (),
        t if gap or fresh else state.since,
        rows,
        next_row,
        state.next_analysis,
        state.samples + 1,
        state.missing + missing,
        state.tracking,
    )
    if gap:
        state = _counted(state, gaps=1)
        if dt > model.stale:  # the history says nothing about now
            tracking = replace(state.tracking, times=np.empty(0), values=np.empty((0, CHANNELS)))
            state = state._replace(rows=rows[-1:], tracking=tracking)
    if t >= state.next_analysis:
        state = _analyse(model, state)
    return state


def _glitch(model: Model, state: State, sample: tuple[float, ...], dt: float) -> tuple[State, tuple[float, ...] | None]:
    """A sample far from the last: dropped (a glitch), or, once ``rebase_samples`` in a row stay
    together, taken as a re-zero whose step goes into the offset (history and lock carry on)."""
    suspect = state.suspect
    if suspect and not _far(model, suspect[-1], sample, dt):
        suspect = (*suspect, sample)
    else:
        suspect = (sample,)
    if len(suspect) < model.rebase_samples:
        return _counted(state._replace(suspect=suspect), glitches=1), None
    first = suspect[0]  # the step happened between the last good sample and the first suspect
    jump = tuple(0.0 if math.isnan(s) or math.isnan(p) else s - p for s, p in zip(first, state.last, strict=True))
    offset = tuple(o + d for o, d in zip(state.offset, jump, strict=True))
    shifted = tuple(s - d for s, d in zip(sample, jump, strict=True))
    state = _counted(state._replace(offset=offset, suspect=()), glitches=1 - len(suspect), rebases=1)
    return state, shifted


def _history(model: Model, state: State) -> Tracking:
    """Pending rows moved into the arrays, rows older than ``model.history`` dropped."""
    tracking = state.tracking
    if state.rows:
        block = np.array(state.rows, dtype=np.float64)
        times = np.concatenate([tracking.times, block[:, 0]])
        values = np.concatenate([tracking.values, block[:, 1:]])
    else:
        times, values = tracking.times, tracking.values
    keep = int(np.searchsorted(times, state.t - model.history))
    return replace(tracking, times=times[keep:], values=values[keep:])


def _wrap(x: float, turn: float = 1.0) -> float:
    """``x`` into [-turn/2, turn/2): a phase difference in strides (modulo half a stride with ``turn=0.5``)."""
    return (x + 0.5 * turn) % turn - 0.5 * turn


def _dense_enough(model: Model, times: FloatArray, t: float) -> bool:
    recent = times[times >= t - 1.2]
    return bool(len(recent) >= model.min_rate * 1.2)


def _analyse(model: Model, state: State) -> State:
    """One analysis at the last sample's time: fit, then steer, switch, hold or let go."""
    t = state.t
    tr = _history(model, state)
    fit = None
    dense = _dense_enough(model, tr.times, t)
    if dense:
        current = tr.track.gait if tr.lock is Lock.LOCKED and tr.track else None
        window = min(max(model.beat_beats / tr.fit.beat, model.beat_window[0]), model.beat_window[1]) if tr.fit else 1.2
        fit = analyse(
            tr.times,
            tr.values,
            model.templates,
            window_strides=model.window_strides,
            beat_window=window,
            current=current,
            stay=model.stay,
            near=tr.track.frequency * model.templates[tr.track.gait].beats if current and tr.track else None,
        )
        tr = _baseline(model, tr, t, fit)
    tr = replace(tr, fit=fit, counters=replace(tr.counters, analyses=tr.counters.analyses + 1))
    sure = tr.lock is Lock.LOCKED and tr.fit is not None and tr.fit.score >= model.lock_score
    period = model.analysis_period if sure else model.search_period
    state = state._replace(rows=(), next_analysis=t + period)
    if fit is None:  # too sparse a stream, or too short a history for the beat found
        return _settle(model, state, tr, Lock.SEARCHING if dense else Lock.NO_SIGNAL, miss=True)
    if fit.gait is None:
        return _settle(model, state, tr, Lock.STILL, force=True)
    template = model.templates[fit.gait]
    measured = fit.phase + fit.stride * (t - fit.t)
    turn = 0.5 if fit.half else 1.0  # without the sideways axes a diagonal pair is a coin toss: keep ours
    track = tr.track
    if fit.half and track is not None and track.gait is fit.gait:
        measured = track.phase(t) + _wrap(measured - track.phase(t), turn)
    locked = tr.lock is Lock.LOCKED and track is not None and track.gait is fit.gait
    good = fit.score >= (model.keep_score if locked else model.lock_score)
    if locked and good and track is not None:
        error = _wrap(measured - track.phase(t))
        if abs(error) <= 2.0 * model.confirm_phase:
            frequency = track.frequency + model.frequency_gain * (fit.stride - track.frequency)
            rate = frequency + model.pll_gain * error / model.analysis_period
            speed = template.speed_at(frequency)
            steered = Track(fit.gait, track.phase(t), t, rate, frequency, speed, track.distance(t))
            return _settle(model, state, replace(tr, track=steered, candidate=None), Lock.LOCKED)
    if good:
        travelled = track.distance(t) if track is not None else 0.0
        fresh = Track(fit.gait, measured, t, fit.stride, fit.stride, template.speed_at(fit.stride), travelled)
        candidate = tr.candidate
        if (
            candidate is not None
            and candidate.gait is fit.gait
            and abs(_wrap(measured - candidate.phase(t), turn)) <= model.confirm_phase
        ):
            return _switch(model, state, tr, fresh)
        tr = replace(tr, candidate=fresh)
    return _settle(model, state, tr, Lock.SEARCHING, miss=True)


def _switch(model: Model, state: State, tr: Tracking, track: Track) -> State:
    """Lock onto ``track``: the hooves blend from the old track (if any) over ``model.ease``."""
    previous = tr.track if tr.lock is Lock.LOCKED else None
    counters = replace(tr.counters, locks=tr.counters.locks + 1)
    tr = replace(tr, track=track, previous=previous, switched=state.t, candidate=None, counters=counters)
    return _settle(model, state, tr, Lock.LOCKED)


def _settle(model: Model, state: State, tr: Tracking, lock: Lock, *, miss: bool = False, force: bool = False) -> State:
    """Apply a new lock state and the weights. A lock, and a still saddle, survive ``model.misses``
    analyses without a fit unless ``force`` (a still saddle's beat is noise: some analyses find
    none, and the state must not flicker between ``still`` and ``searching``)."""
    missed = tr.missed + 1 if miss else 0
    if tr.lock is Lock.LOCKED and lock is not Lock.LOCKED and missed < model.misses and not force:
        lock = Lock.LOCKED  # hold: the oscillator runs on
    elif tr.lock is Lock.STILL and lock is not Lock.LOCKED and missed < model.misses and not force:
        lock = Lock.STILL
    counters = tr.counters
    if tr.lock is Lock.LOCKED and lock is not Lock.LOCKED:
        counters = replace(counters, losses=counters.losses + 1)
    t = state.t
    track = tr.track
    ease = model.ease_time(track.frequency if track is not None else 0.0)
    hooves = tr.hooves.toward(1.0 if lock is Lock.LOCKED else 0.0, t, ease)
    fit = tr.fit
    steady = t - state.since >= model.continuous
    motion = fit is not None and (lock is Lock.LOCKED or fit.smooth >= model.smooth_residual or fit.gait is None)
    pose = tr.pose.toward(1.0 if steady and motion else 0.0, t, model.ease)
    tr = replace(tr, lock=lock, missed=missed, hooves=hooves, pose=pose, counters=counters)
    return state._replace(tracking=tr)


def _baseline(model: Model, tr: Tracking, t: float, fit: Fit | None) -> Tracking:
    """The baseline after an analysis at ``t`` (:func:`riderlive.saddle.baseline.baseline`)."""
    periodic = fit is not None and fit.gait is not None and fit.score >= model.keep_score
    window = fit if periodic else None
    drift, level = baseline(
        tr.times,
        tr.values,
        t,
        window=window,
        point=model.point,
        drift=tr.drift,
        level=tr.level,
        levels=tr.levels,
        timing=model,
    )
    return replace(tr, drift=drift, level=level, levels=tr.levels + 1)
