"""Resampling a live input stream onto the tick (pure: no clocks, no I/O).

Frames arrive with the producer's own time ``t`` (seconds, any origin) and the
receive time (engine seconds). The producer's clock is mapped onto the engine's by
the least-delayed frames: the line ``engine = offset + rate * t`` below every buffered
frame (``receive - rate * t`` at its least), so the mapping follows the producer's
clock but not its network jitter. The tick then reads the stream ``delay`` seconds in
the past:

- between two frames: linear interpolation;
- before the oldest buffered frame: the oldest frame;
- after the newest frame: the newest frame held, for at most ``hold`` seconds of
  source time; beyond that the stream is stale (None). Nothing is extrapolated.

**Clock rate** (docs/protocol.md, "Clocks that drift"): a producer's clock may run a few
per cent slow or fast against ours (a game stepping a fixed timestep on a busy host).
With the rate taken as 1, the least-delayed frame of a slow clock is the oldest one
buffered: the tick's reading ran ahead of the newest frame by up to 5 % of the buffer's
span (0.21 s at 120 Hz, 0.43 s at 60 Hz), holding the newest frame on every tick, and
past ``hold`` the stream went stale (at 60 Hz: 79 % of ticks neutral). So the rate is
estimated: the least-delayed frame of each window of :data:`RATE_EVERY_S` of source time
is kept (the last :data:`RATE_WINDOWS`: 10 s), and at the end of each window, once they
span :data:`RATE_SPAN_S`, ``rate = 1 + d(receive - t) / dt`` between the least-delayed
of the oldest and of the newest third, bounded to 1 +- :data:`MAX_SKEW`; a change of the
producer's rate (of the windows of the last :data:`CHANGE_SPAN_S`, the slope from the middle
third's least-delayed frame to the newest third's :data:`RATE_CHANGE` from the whole
baseline's) restarts the baseline from the newest third, so the rate follows in seconds. At each new
estimate the mapping is kept continuous at the newest frame; then, at each frame, it moves
toward the line (at that rate) through the least-delayed frame of the last second (lowered
by a less-delayed frame) by at most :data:`MAX_SKEW` of the frame's source time step: the
tick's reading never steps, it runs at most 10 % slower or faster while it catches up.
Cost: a few comparisons per frame, ~40 per window.

The mapping is :class:`ClockMap`, one per stream: the horse :class:`Resampler`'s, and the
saddle input's (``realtime/saddle_input.py``), which steps its estimator per sample
instead of buffering frames.
"""

from __future__ import annotations

import bisect
from collections import deque
from dataclasses import dataclass, field

MAX_SKEW = 0.1
"""A producer's clock rate is taken within 1 +- this of ours (a faster or slower clock is
mapped at the bound: its frames then run ahead or behind, held or stale, as before)."""
RATE_SPAN_S = 1.0
"""The source time the buffer spans before the first rate estimate (s)."""
RATE_EVERY_S = 0.25
"""Source time between two estimates (s), each a window whose least-delayed frame is kept."""
RATE_WINDOWS = 40
"""Windows kept for the rate (10 s of source time at most): the baseline of the estimate."""
RATE_CHANGE = 0.01
"""A slope between the least-delayed frames of the middle and the newest third of the last
:data:`CHANGE_SPAN_S` of windows this far from the whole baseline's is a change of the
producer's rate (a game that slows when the host gets busy): the baseline restarts from the
newest third, so the estimate follows in seconds, not the baseline's 10 s. Judged only once
each third spans a second and the two least-delayed frames compared lie a second apart: the
least-delayed frame of a second is an on-time one, so delivery stalls and a stream's bursty
first seconds do not reach it."""
CHANGE_SPAN_S = 4.5
"""Source seconds of the newest windows a change of rate is judged on (thirds of 1.5 s). A
slowed clock's least-delayed frames are the earliest of each third, so the change shows only
once the middle third has passed it: judged on the whole 10 s baseline (thirds of 3.3 s),
a 5 % slowing 12 s into a stream was followed in 4.0-6.4 s; on 4.5 s, 2.2-2.7 s
(``bench/bench_rate_follow.py``), as robust to delivery stalls (thirds of 1 s were not:
a steady clock's rate 1.5 % off under sustained slow deliveries)."""


@dataclass
class ClockMap:
    """A producer's clock mapped onto the engine's (see the module docstring): the offset of
    the least-delayed of the last ``capacity`` frames, then, once estimated, the line
    ``engine = anchor + rate * t``. One per stream: the horse resampler's and the saddle
    input's (``realtime/saddle_input.py``). Times in seconds (``t`` producer, ``received``
    engine)."""

    capacity: int = 512
    offsets: deque[float] = field(default_factory=deque)
    """``received - t`` of the last ``capacity`` frames."""
    offset: float | None = None
    """Engine time minus producer time of the least-delayed of them (the mapping while no
    rate is estimated)."""
    rate: float = 1.0
    """Engine seconds per producer second (1 until estimated; within 1 +- MAX_SKEW)."""
    anchor: float | None = None
    """With a rate estimated: engine time of producer time 0 on the mapping line (None: none yet)."""
    target: float = 0.0
    """The anchor of the line under the recent frames at ``rate``: ``anchor`` moves to it
    by at most ``MAX_SKEW`` of each frame's source time step."""
    newest: float | None = None
    """Producer time of the newest frame (None: none yet)."""
    estimated_at: float = 0.0
    """Producer time of the newest frame at the last rate estimate."""
    windows: deque[tuple[float, float]] = field(default_factory=lambda: deque(maxlen=RATE_WINDOWS))
    """The least-delayed frame ``(t, receive - t)`` of each of the last ``RATE_WINDOWS``
    windows of ``RATE_EVERY_S`` (a longer baseline than the buffer's: a steadier rate)."""
    least: tuple[float, float] | None = None
    """The least-delayed frame of the window under way."""

    def clear(self) -> None:
        self.offsets.clear()
        self.offset = None
        self.rate = 1.0
        self.anchor = None
        self.target = 0.0
        self.newest = None
        self.estimated_at = 0.0
        self.windows.clear()
        self.least = None

    def push(self, t: float, received: float) -> None:
        """Map one more frame (``t`` after every frame pushed before: the caller drops the others)."""
        previous, self.newest = self.newest, t
        offset = received - t
        self.offsets.append(offset)
        if self.offset is None or offset < self.offset:
            self.offset = offset
        if len(self.offsets) > self.capacity and self.offsets.popleft() == self.offset:
            self.offset = min(self.offsets)
        if self.anchor is not None and previous is not None:
            self.target = min(self.target, received - self.rate * t)  # a less-delayed frame
            step = MAX_SKEW * (t - previous)  # the read runs at most 10 % slower or faster
            self.anchor += min(step, max(-step, self.target - self.anchor))
        if self.least is None or offset < self.least[1]:
            self.least = (t, offset)
        if t - self.estimated_at >= RATE_EVERY_S:
            self.windows.append(self.least)
            self.least = None
            self.estimated_at = t
            if self.windows[-1][0] - self.windows[0][0] >= RATE_SPAN_S:
                self._estimate_rate(t)

    def restart_rate(self, t: float) -> None:
        """Forget the rate's windows, not the mapping or the rate in use: the offsets up to
        producer time ``t`` are not comparable with those after it, and a rate from windows on
        both sides would take the step for a slope (bound to 1 +- MAX_SKEW). The saddle input's
        after a delivery stall (its backlog's windows were all late: ``realtime/saddle_input.py``);
        both paths' at a frame where the service re-anchored the producer's clock (a pause, a
        resume, a step back: its time given from one arrival, ``TickCore.push_input``)."""
        self.windows.clear()
        self.least = None
        self.estimated_at = t

    def _estimate_rate(self, newest: float) -> None:
        """A new rate from the least-delayed frames of the oldest and the newest third of the
        windows; the mapping kept continuous at ``newest`` and aimed at the line through the
        least-delayed frame of the last second (not the whole baseline's: a rate a little
        off would put the line under the old frames, ahead of the new ones)."""
        windows = list(self.windows)
        third = max(1, len(windows) // 3)
        ta, oa = min(windows[:third], key=lambda w: w[1])
        tb, ob = min(windows[-third:], key=lambda w: w[1])
        if tb - ta < RATE_SPAN_S / 2:
            return
        skew = (ob - oa) / (tb - ta)
        recent = windows[-round(CHANGE_SPAN_S / RATE_EVERY_S) :]
        part = len(recent) // 3
        if part * RATE_EVERY_S >= RATE_SPAN_S and len(recent) > 2 * part:  # thirds of a second or more
            tm, om = min(recent[part:-part], key=lambda w: w[1])
            tn, on = min(recent[-part:], key=lambda w: w[1])
            if tn - tm >= RATE_SPAN_S and abs((on - om) / (tn - tm) - skew) > RATE_CHANGE:
                # the clock's rate changed within the baseline: it restarts from the newest third
                for _ in range(len(windows) - part):
                    self.windows.popleft()
                skew = (on - om) / (tn - tm)
        skew = min(MAX_SKEW, max(-MAX_SKEW, skew))
        rate = 1.0 + skew
        before = self.offset if self.anchor is None else self.anchor
        assert before is not None  # a frame was pushed
        self.anchor = before + (self.rate - rate) * newest  # the newest frame maps where it did
        recent = windows[-max(1, round(1.0 / RATE_EVERY_S)) :]
        self.target = min(o + t - rate * t for t, o in recent)  # receive - rate * t
        self.rate = rate

    def engine_time(self, t: float) -> float | None:
        """The engine time producer time ``t`` maps to (None before the first frame)."""
        if self.anchor is not None:
            return self.anchor + self.rate * t
        if self.offset is None:
            return None
        return t + self.offset

    def source_time(self, now: float, delay: float) -> float | None:
        """The producer time the tick at engine time ``now`` shows, ``delay`` (s) behind the mapping."""
        if self.anchor is not None:
            return (now - self.anchor) / self.rate - delay
        if self.offset is None:
            return None
        return now - self.offset - delay


@dataclass
class Resampler:
    """The buffered frames of one producer, and its :class:`ClockMap`."""

    delay: float = 0.01
    hold: float = 0.25
    capacity: int = 512
    times: deque[float] = field(default_factory=deque)
    frames: deque[list[float]] = field(default_factory=deque)
    clock: ClockMap = field(init=False)

    def __post_init__(self) -> None:
        self.clock = ClockMap(self.capacity)

    @property
    def rate(self) -> float:
        """The producer's clock rate in use (engine seconds per producer second)."""
        return self.clock.rate

    @property
    def offset(self) -> float | None:
        """The least-delayed buffered frame's engine minus producer time (``ClockMap.offset``)."""
        return self.clock.offset

    @property
    def anchor(self) -> float | None:
        return self.clock.anchor

    def clear(self) -> None:
        self.times.clear()
        self.frames.clear()
        self.clock.clear()

    def push(self, t: float, received: float, values: list[float]) -> bool:
        """Add a frame; a frame not newer than the newest is dropped (returns False)."""
        if self.times and t <= self.times[-1]:
            return False
        self.times.append(t)
        self.frames.append(values)
        if len(self.times) > self.capacity:
            self.times.popleft()
            self.frames.popleft()
        self.clock.push(t, received)
        return True

    def source_time(self, now: float) -> float | None:
        """The producer time the tick at engine time ``now`` should show."""
        return self.clock.source_time(now, self.delay)

    def sample(self, now: float) -> tuple[float, list[float]] | None:
        """``(source time, frame)`` for engine time ``now``, or None when stale or empty."""
        query = self.source_time(now)
        if query is None:
            return None
        times = self.times
        if query >= times[-1]:
            if query - times[-1] > self.hold:
                return None
            return times[-1], self.frames[-1]
        if query <= times[0]:
            return times[0], self.frames[0]
        i = bisect.bisect_right(times, query)
        t0, t1 = times[i - 1], times[i]
        a = (query - t0) / (t1 - t0)
        f0, f1 = self.frames[i - 1], self.frames[i]
        return query, [x + (y - x) * a for x, y in zip(f0, f1, strict=True)]
