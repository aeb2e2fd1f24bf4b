"""The saddle in the tick: a saddle stream driving the rider, and the saddle pose of every tick.

Pure (no clocks, no I/O); every time argument is seconds, engine or producer as named.

- :class:`SaddleInput`: the driving saddle producer's stream. Each received sample is
  stepped through the estimator (:func:`riderlive.saddle.step`) in source-time order,
  so a 1000 Hz stream is seen sample by sample, not once per tick. The tick reads the
  stream at the producer's time that corresponds to its own (the horse resampler's
  clock mapping, :class:`~riderlive.realtime.resample.ClockMap`: the least-delayed
  sample of the last 256, then the producer's clock rate tracked, docs/protocol.md
  "Clocks that drift") less a **delay**: ``input.delay``, raised by the stream's recent
  lateness (the latest arrival over the last :data:`LATE_MEMORY_S` of the stream, judged
  on the producer's clock rate as it is known: :class:`Lateness`) up
  to :data:`MAX_DELAY`, and changed
  by at most :data:`DELAY_SLEW` seconds per second (the stream slowed or sped up by
  that fraction, never stepped). Within the samples received the frame is the one an
  offline bake of the same samples rebuilds (:func:`riderlive.saddle.rebuild`: the
  estimator's state after each sample, :func:`riderlive.saddle.horse_frame` at that
  sample's time), interpolated linearly between the two around the read time: samples
  that arrive late in bursts (a busy host) give the bake's motion, not a pose held then
  caught up in one tick. Past the newest sample the estimator extrapolates the hooves
  and holds the measured pose; after the last sample it runs on for ``Model.hold``
  (0.5 s) and eases to standing over ``Model.ease`` (0.25 s); after that the stream is
  *stale* (counted) and the tick eases the rider to neutral as for a horse stream that
  stops.
- :func:`saddle_pose`: ``channels.SADDLE`` of any horse frame, in the service's units
  (what ``/ws/rider`` publishes and takes record, whatever drives).
- :func:`estimate_row`: the estimate as the output record carries it (codes and numbers).

The input ring carries lengths in the service unit (``length_scale / 25`` metres); the
estimator speaks metres and degrees, so lengths are converted on the way in and out.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

from riderlive.horse.gaits import Gait
from riderlive.realtime.resample import ClockMap
from riderlive.saddle import Lock, Model, SaddlePoint, State, estimate, horse_frame, saddle_from_horse, step
from riderlive.saddle.pose import BEND_COLUMN, SCALAR, TRUNK_COLUMNS, saddle_from_trunk
from riderlive.units import horse_lengths, metres_per_unit, saddle_lengths

LOCKS: tuple[str, ...] = tuple(lock.value for lock in Lock)
"""Lock states by their code in a record (``no_signal`` 0, ``still`` 1, ``searching`` 2, ``locked`` 3)."""
GAITS: tuple[str, ...] = tuple(gait.value for gait in Gait)
"""Gaits by their code in a record (``walk`` 0 ... ``halt`` 4)."""
NO_ESTIMATE: tuple[float, ...] = (math.nan,) * 5
"""The estimate of a record no saddle input drives."""
COUNTERS: tuple[str, ...] = ("samples", "missing", "empty", "gaps", "glitches", "rebases", "locks", "losses")
"""Estimator counters summed over every saddle stream the tick has seen (``saddle_<name>``)."""
_OFFSETS = 256
"""Samples whose clock offset the mapping takes the least of."""
LATE_WINDOW_S = 0.25
"""Source seconds per window of :class:`Lateness` (its latest arrival kept)."""
LATE_MEMORY_S = 10.0
"""Source seconds of lateness the delay follows: a busy host stalls a producer or the service
every few seconds, so the delay stays at the stalls' lateness between them instead of decaying
(a memory of 256 samples, 1.28 s at 200 Hz, let it fall between stalls: each stall then read
past the newest sample, and stepped back to the bake's frames when the samples came, the
one-tick steps of 0.5-1.2 deg on ``lower_back.rz``; docs/performance.md)."""
_HISTORY = 512
"""Estimator states kept to read between samples (0.5 s at 1000 Hz: more than :data:`MAX_DELAY`)."""
MAX_DELAY = 0.25
"""The most the read time trails the stream (s): lateness beyond it is held, not waited for."""
DELAY_SLEW = 0.1
"""Seconds the delay changes per second of engine time, at most (the stream plays at 0.9-1.1x meanwhile)."""


def saddle_pose(horse: Sequence[float], to_metres: float, point: SaddlePoint) -> list[float]:
    """``channels.SADDLE`` of one horse frame (service length units in and out, degrees)."""
    if to_metres == 1.0:
        return saddle_from_horse(horse, point)
    trunk = [horse[i] * to_metres if k < 3 else horse[i] for k, i in enumerate(TRUNK_COLUMNS)]
    out = saddle_from_trunk(trunk, horse[BEND_COLUMN], point, SCALAR)
    return [v / to_metres if k < 3 else v for k, v in enumerate(out)]


def estimate_row(state: State, t: float) -> tuple[float, ...]:
    """The estimate at producer time ``t`` as a record carries it (``record.ESTIMATE_FIELDS``)."""
    found = estimate(state, t)
    gait = GAITS.index(found.gait) if found.gait is not None else math.nan
    age = found.age if found.age is not None else math.nan
    return (float(LOCKS.index(found.lock)), float(gait), found.stride_hz, found.phase, age)


Arrival = tuple[float, float]
"""A sample's source time and its raw offset, ``received - t`` (s)."""


def _late(most: Arrival, least: Arrival, skew: float) -> float:
    """How much later ``most`` arrived than ``least``, on a clock running ``1 + skew`` x ours (s)."""
    return (most[1] - least[1]) - skew * (most[0] - least[0])


@dataclass
class Lateness:
    """The latest arrival of a stream's samples over its last :data:`LATE_MEMORY_S` (s of
    source time), each against the least-delayed of its own :data:`LATE_WINDOW_S` window and
    the one before (so a rate still being tracked adds at most its residual over 0.5 s, while
    a stall's burst is measured against the on-time samples before it). Each window keeps its
    latest and least-delayed arrivals and the clock's rate then, not a number: its lateness
    is the lesser judged on that rate and on the rate *as now known* (``skew``: rate - 1).
    So the ramp that a change of the producer's rate put into the windows before the
    estimate followed it leaves the delay once it has (a 5 % change held the delay ~25 ms up
    for the whole memory), the windows before the change stay as they were, and a stall's
    lateness, far beyond either rate's, stays. A few comparisons a sample; the closed
    windows are judged again only when a window closes or the rate changes."""

    windows: deque[tuple[Arrival, Arrival, Arrival, float]] = field(
        default_factory=lambda: deque(maxlen=round(LATE_MEMORY_S / LATE_WINDOW_S))
    )
    """Each closed window's latest arrival, its least-delayed, the one before's, and the skew then."""
    most: Arrival | None = None
    least: Arrival | None = None
    least_before: Arrival | None = None
    started: float | None = None
    """Source time the window under way started at (None: no sample yet)."""
    _closed: tuple[float, float] | None = None
    """(skew, latest of the closed windows) last judged."""

    def clear(self) -> None:
        self.windows.clear()
        self.most = self.least = self.least_before = None
        self.started = None
        self._closed = None

    def add(self, t: float, offset: float, skew: float) -> None:
        """A sample at source time ``t`` arrived ``offset`` (= received - t) s after it, on a
        clock estimated at ``1 + skew`` x ours (which arrival is a window's latest is judged so)."""
        if self.started is None:
            self.started = t
        elif t - self.started >= LATE_WINDOW_S and self.most is not None and self.least is not None:
            self.windows.append((self.most, self.least, self.least_before or self.least, skew))
            self._closed = None
            self.least_before, self.least, self.most, self.started = self.least, None, None, t
        here = (t, offset)
        if self.least is None or _late(here, self.least, skew) < 0.0:
            self.least = here
        if self.most is None or _late(here, self.most, skew) > 0.0:
            self.most = here

    def _current(self, skew: float) -> float:
        assert self.most is not None and self.least is not None
        before = self.least_before or self.least
        return max(_late(self.most, self.least, skew), _late(self.most, before, skew))

    def latest(self, skew: float) -> float | None:
        """The latest arrival remembered (s) on a clock at ``1 + skew`` x ours, None before the first sample."""
        if self.most is None:
            return None
        if self.windows and (self._closed is None or self._closed[0] != skew):
            closed = max(
                min(max(_late(m, a, k), _late(m, b, k)) for k in (then, skew)) for m, a, b, then in self.windows
            )
            self._closed = (skew, closed)
        current = self._current(skew)
        return max(current, self._closed[1]) if self._closed is not None else current


@dataclass(frozen=True)
class _Kept:
    """A cleared stream's estimator, kept for a new stream that continues it."""

    state: State
    history: tuple[State, ...]
    times: tuple[float, ...]
    received: float
    """Engine time its newest sample was received at (s)."""


@dataclass
class SaddleInput:
    """The driving saddle stream in the tick: the estimator's state and the clock mapping."""

    model: Model
    to_metres: float = 1.0
    """Service length unit -> metres."""
    base_delay: float = 0.0
    """The least delay (s): ``input.delay``."""

    def __post_init__(self) -> None:
        self._samples = saddle_lengths(self.to_metres)
        """A sample's lengths to metres (the estimator's unit)."""
        self._frames_out = horse_lengths(self.to_metres)
        """A rebuilt horse frame's lengths back to the service unit."""
        self.state = State()
        self.clock = ClockMap(_OFFSETS)
        """The producer's clock mapped onto the engine's (rate tracked)."""
        self.lateness = Lateness()
        """The recent samples' arrivals, judged on the clock's rate as it is known (s)."""
        self._rate_known = False
        """Whether ``lateness`` was measured with the clock's rate estimated (the first estimate
        forgets what was measured before it: the stream's start, against a mapping that knew
        no rate)."""
        self.history: deque[State] = deque(maxlen=_HISTORY)
        """The estimator's state after each recent sample (its ``t`` is that sample's time)."""
        self.times: deque[float] = deque(maxlen=_HISTORY)
        self._frames: dict[float, list[float]] = {}
        """Rebuilt frames of the two samples last read around (by sample time)."""
        self.delay = self.base_delay
        """The read time's delay now (s)."""
        self._delay_at: float | None = None
        """Engine time the delay was last moved at (None: a new stream, the delay starts at its target)."""
        self.stale = False
        self.finished = dict.fromkeys(COUNTERS, 0)
        """Counters of the streams before the current one."""
        self.stale_episodes = 0
        """Times a driving saddle stream went stale (the rider eased to neutral)."""
        self._last_received: float | None = None
        """Engine time the newest sample was received at (None: none in this stream)."""
        self._kept: _Kept | None = None
        """The estimator of the stream before the last :meth:`clear`, until the next sample."""
        self._draining: float | None = None
        """After a continued stream: the offset (received - t) of its newest sample while they
        come faster than the producer's clock (its backlog draining); None otherwise."""
        self.continued = 0
        """New streams that went on with the estimator of the one before (:meth:`push`)."""

    def clear(self) -> None:
        """A new stream (another producer, a new segment, a producer gone): start afresh, the
        estimator's state kept aside for a new stream that continues it (:meth:`push`)."""
        for name, value in self._current().items():
            self.finished[name] += value
        if self.history and self._last_received is not None:
            self._kept = _Kept(self.state, tuple(self.history), tuple(self.times), self._last_received)
        self.state = State()
        self.clock.clear()
        self.lateness.clear()
        self._rate_known = False
        self.history.clear()
        self.times.clear()
        self._frames.clear()
        self.delay, self._delay_at = self.base_delay, None
        self.stale = False
        self._last_received = self._draining = None

    def _continue(self, t: float, received: float) -> None:
        """The first sample of a new stream: if it follows the kept estimator's newest sample
        within ``Model.max_interval`` of the producer's time (not a gap to the estimator) and
        :data:`LATE_MEMORY_S` of ours, the stream goes on with that estimator (its lock, its
        history to read between samples); only the clock mapping and the lateness start afresh.
        That is a producer whose delivery stalled longer than ``input.clock_jump``: the endpoint
        takes the stall for a clock jump and starts a new segment, but the samples are the
        device's own, one sample interval apart; starting the estimator afresh lost the lock
        for seconds (docs/performance.md). A real jump (a clock set or restarted) is far from
        the newest sample and starts afresh as before."""
        kept, self._kept = self._kept, None
        if kept is None or not 0.0 < t - kept.state.t <= self.model.max_interval:
            return
        if received - kept.received > LATE_MEMORY_S:
            return
        counters = estimate(kept.state).counters  # folded into ``finished`` by clear(): not twice
        for name in COUNTERS:
            self.finished[name] -= counters[name]
        self.state = kept.state
        self.history.extend(kept.history)
        self.times.extend(kept.times)
        self._draining = math.inf  # the first sample starts it
        self.continued += 1

    def _drain(self, t: float, previous: float, received: float) -> None:
        """While a continued stream's backlog drains (each sample arriving earlier against its
        time than the one before by over half its step: faster than twice its clock), the clock
        mapping's rate starts over from it (``ClockMap.restart_rate``): a rate from the backlog's
        windows was the bound, 10 % off, and the read ran past the newest sample for seconds."""
        if self._draining is None:
            return
        offset = received - t
        if offset < self._draining - (t - previous) / 2:
            self.clock.restart_rate(t)
            self._draining = offset
        else:
            self._draining = None

    def _current(self) -> dict[str, int]:
        counters = estimate(self.state).counters
        return {name: counters[name] for name in COUNTERS}

    def counters(self) -> dict[str, int]:
        """Every stream's counters so far, and ``stale``."""
        current = self._current()
        out = {name: self.finished[name] + current[name] for name in COUNTERS}
        out["stale"] = self.stale_episodes
        return out

    def push(self, t: float, received: float, values: Sequence[float]) -> bool:
        """Step the estimator with one sample (service units, NaN for a missing axis).

        False (and nothing changes) for a sample not after the last one.
        """
        if self._kept is not None:
            self._continue(t, received)
        if not t > self.state.t:
            return False
        previous, self._last_received = self.state.t, received
        self.state = step(self.model, self.state, t, self._samples.to_metres(values[:6]))
        if self.state.t == t:  # taken (an empty sample is counted and leaves the pose as it was)
            self.history.append(self.state)
            self.times.append(t)
        clock = self.clock
        clock.push(t, received)
        self._drain(t, previous, received)
        if clock.anchor is not None and not self._rate_known:
            self.lateness.clear()
            self._rate_known = True
        self.lateness.add(t, received - t, clock.rate - 1.0)
        self.stale = False
        return True

    def source_time(self, now: float) -> float | None:
        """The producer time shown at engine time ``now``: ``delay`` behind the clock mapping."""
        return self.clock.source_time(now, self.delay)

    def _move_delay(self, now: float) -> None:
        """Toward the base delay plus the recent samples' lateness (see the module docstring)."""
        late = self.lateness.latest(self.clock.rate - 1.0)
        if late is None:
            return
        target = min(self.base_delay + max(0.0, late), MAX_DELAY)
        if self._delay_at is None:
            self.delay = target
        else:
            most = DELAY_SLEW * max(0.0, now - self._delay_at)
            self.delay += min(max(target - self.delay, -most), most)
        self._delay_at = now

    def _frame(self, state: State) -> list[float]:
        """The horse frame an offline bake rebuilds at this state's sample (cached for the next ticks)."""
        frame = self._frames.get(state.t)
        if frame is None:
            if len(self._frames) >= 2:
                self._frames.clear()
            frame = self._frames[state.t] = horse_frame(self.model, state, state.t)
        return frame

    def _between(self, query: float) -> list[float]:
        """The bake's frames at the samples around ``query`` (within the history), interpolated."""
        times = self.times
        if query <= times[0]:
            return self._frame(self.history[0])
        i = bisect.bisect_right(times, query)
        t0, t1 = times[i - 1], times[i]
        f0, f1 = self._frame(self.history[i - 1]), self._frame(self.history[i])
        a = (query - t0) / (t1 - t0)
        return [x + (y - x) * a for x, y in zip(f0, f1, strict=True)]

    def sample(self, now: float) -> tuple[float, list[float]] | None:
        """``(producer time, horse frame in service units)`` at engine time ``now``, or None when stale."""
        self._move_delay(now)
        query = self.source_time(now)
        if query is None:
            return None
        if query < self.state.t:
            return query, self._frames_out.from_metres(self._between(query))
        if query - self.state.t > self.model.hold + self.model.ease:
            if not self.stale:
                self.stale = True
                self.stale_episodes += 1
            return None
        return query, self._frames_out.from_metres(horse_frame(self.model, self.state, query))

    def estimate_row(self, now: float) -> tuple[float, ...]:
        query = self.source_time(now)
        return NO_ESTIMATE if query is None else estimate_row(self.state, max(query, self.state.t))


def make_saddle_input(length_scale: float, point: SaddlePoint, delay: float = 0.0) -> SaddleInput:
    """The tick's saddle input for a service speaking ``length_scale`` rig units per its length unit,
    reading the stream at least ``delay`` (s, ``input.delay``) behind its clock mapping."""
    return SaddleInput(Model(point=point), metres_per_unit(length_scale), delay)
