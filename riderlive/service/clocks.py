"""A producer's clock against the service's: jumps, backward steps, a clock that stands
still (pure: state in, state out; docs/protocol.md, "Clocks that jump").

Each frame brings the producer's time ``t`` and its receive time ``rx`` (engine
seconds). :func:`clock_step` decides the time the tick is given for it and whether a
new *segment* starts (a ``segment`` message to the producer):

- **jump** (``clock_forward`` / ``clock_backward``): between two frames the producer's
  clock moved more than ``jump_s`` more or less than the service's: a new stream for the
  tick (a fresh clock mapping, a blend), on the producer's own clock;
- **step back** (``clock_backward``): ``t`` went back by more than :data:`STEP_S`
  but less than a jump (a clock stepped by NTP, a game's time scale reset). Without a
  re-anchor the tick would drop every frame until ``t`` passed its old newest, and its
  clock mapping would stay ``step`` off for seconds. Re-anchored: the time given goes
  on from the newest with the service's clock (at least one typical clock step: a frame
  of a burst after a delivery stall arrives ~0 s after the one before, though the
  producer made it a step later), ``t`` plus an offset from then on;
- **paused** (``clock_paused``): frames keep coming but ``t`` has not moved for
  :data:`PAUSE_STEPS` of the producer's own clock steps (the median of its last
  :data:`STEPS_KEPT`; at least :data:`MIN_PAUSE_S`, at most ``pause_s``): a paused game, a
  frozen sensor timestamp. The service's clock stands in for the producer's (the time
  given goes on from the newest with the service's seconds), so the producer keeps
  driving with its frames as they come. Frames of a freeze before it is noticed are
  dropped as not newer: noticed within a few frames, the tick's read (which trails the
  newest sample by its delivery) never runs past the samples into a held pose that then
  steps to the stand-in's (a fixed 0.1 s did at 200 Hz: docs/performance.md);
- **resumed** (``clock_resumed``): the clock moves again after a pause: its own ``t``
  again, plus the offset that keeps the time given continuous.

Steps back, pauses and resumes keep the tick's stream (no jump, no blend: the time
given never goes back); only jumps start a new one.

Steps back and pauses start at most :data:`MAX_SEGMENTS_PER_S` segments a second (a
clock that goes back on every frame would blend forever): beyond that its frames are
dropped as not newer, as before. Times in seconds.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, replace

STEP_S = 0.001
"""A smaller step back is jitter: the frame is dropped as not newer (no segment)."""
MAX_SEGMENTS_PER_S = 4
PAUSE_STEPS = 4
"""A clock that stands still this many of its typical steps while frames keep coming is paused."""
MIN_PAUSE_S = 0.01
"""The least stand-still taken for a pause (s): a 1000 Hz producer's duplicated frame is not one."""
STEPS_KEPT = 9
"""The producer's clock steps (between frames whose ``t`` moved) its typical step is the median of."""


class ClockEvent(enum.Enum):
    """Why a segment starts (the ``reason`` of the ``segment`` message)."""

    FORWARD = "clock_forward"
    BACKWARD = "clock_backward"
    PAUSED = "clock_paused"
    RESUMED = "clock_resumed"

    @property
    def direction(self) -> str:
        """The ``direction`` label of ``riderlive_clock_jumps_total``."""
        return self.value.removeprefix("clock_")


@dataclass(frozen=True)
class ProducerClock:
    """What the service knows of one producer's clock in the current segment."""

    newest_t: float | None = None
    """The newest ``t`` of this segment (None before the first frame)."""
    last_rx: float = 0.0
    """Receive time of the last frame."""
    moved_rx: float = 0.0
    """Receive time of the last frame whose ``t`` was newer."""
    offset: float = 0.0
    """Added to ``t`` for the tick (0 until a step back or a pause re-anchored it)."""
    newest_eff: float = 0.0
    """The time the tick was given for the newest frame."""
    standin: tuple[float, float] | None = None
    """While paused: (time given, ``rx``) from which the service's clock stands in."""
    segments: tuple[float, ...] = ()
    """Receive times of the step and pause segments of the last second."""
    steps: tuple[float, ...] = ()
    """The last :data:`STEPS_KEPT` forward steps of the producer's ``t`` (s)."""

    def typical_step(self) -> float | None:
        """The median of :attr:`steps` (s; None before the clock moved): the producer's frame
        interval on its own clock, whatever its delivery's bursts."""
        if not self.steps:
            return None
        ordered = sorted(self.steps)
        return ordered[len(ordered) // 2]

    def pause_after(self, pause_s: float) -> float:
        """How long ``t`` may stand still while frames come before it is paused (s)."""
        typical = self.typical_step()
        return pause_s if typical is None else min(pause_s, max(MIN_PAUSE_S, PAUSE_STEPS * typical))


@dataclass(frozen=True)
class ClockStep:
    clock: ProducerClock
    t: float
    """The time the tick is given for this frame."""
    event: ClockEvent | None = None
    jump: float = 0.0
    """How far the producer's clock moved beyond (or short of) the service's, s."""
    previous_t: float | None = None
    new_stream: bool = False
    """A jump: the tick maps the producer's clock afresh (a new stream, a blend). Steps back,
    pauses and resumes keep the stream: the time given stays continuous."""

    @property
    def rebased(self) -> bool:
        """A step back, a pause or a resume: the stream goes on, but the time given is now
        ``t`` plus an offset taken from this one frame's arrival (its delivery delay, a stall's
        included), so the tick's clock rate starts its baseline over here."""
        return self.event is not None and not self.new_stream


def _fresh(
    t: float, rx: float, offset: float, segments: tuple[float, ...], steps: tuple[float, ...] = ()
) -> ProducerClock:
    return ProducerClock(t, rx, rx, offset, t + offset, None, segments, steps)


def _stepped(clock: ProducerClock, step: float) -> tuple[float, ...]:
    return (*clock.steps[1 - STEPS_KEPT :], step)


def clock_step(clock: ProducerClock, t: float, rx: float, jump_s: float, pause_s: float) -> ClockStep:
    """One frame's time; see the module docstring (``pause_s``: the longest stand-still
    before a pause, whatever the producer's rate)."""
    last = clock.newest_t
    if last is None:
        return ClockStep(_fresh(t, rx, 0.0, clock.segments), t)
    recent = tuple(s for s in clock.segments if rx - s < 1.0)
    may_segment = len(recent) < MAX_SEGMENTS_PER_S
    if clock.standin is not None:
        base, rx0 = clock.standin
        now = base + (rx - rx0)  # the service's clock, standing in
        if t > last:  # it moves again: its own clock, continuous with the stand-in
            drift = (t - last) - (rx - clock.moved_rx)
            resumed = _fresh(t, rx, now - t, recent, _stepped(clock, t - last))
            return ClockStep(resumed, now, ClockEvent.RESUMED, drift, last)
        if t < last - STEP_S and may_segment:
            step = _fresh(t, rx, now - t, (*recent, rx), clock.steps)
            return ClockStep(step, now, ClockEvent.BACKWARD, t - last, last)
        return ClockStep(replace(clock, last_rx=rx, newest_eff=now, segments=recent), now)
    drift = (t - last) - (rx - clock.last_rx)
    if abs(drift) > jump_s:
        event = ClockEvent.FORWARD if drift > 0 else ClockEvent.BACKWARD
        return ClockStep(_fresh(t, rx, 0.0, recent, clock.steps), t, event, drift, last, new_stream=True)
    if t > last:
        return ClockStep(_fresh(t, rx, clock.offset, recent, _stepped(clock, t - last)), t + clock.offset)
    since = rx - clock.moved_rx
    if t < last - STEP_S and may_segment:  # re-anchored: on from the newest with the service's clock
        now = clock.newest_eff + max(since, clock.typical_step() or 0.0)
        stepped = _fresh(t, rx, now - t, (*recent, rx), clock.steps)
        return ClockStep(stepped, now, ClockEvent.BACKWARD, t - last, last)
    if since >= clock.pause_after(pause_s) and may_segment:
        now = clock.newest_eff + since
        paused = ProducerClock(last, rx, clock.moved_rx, clock.offset, now, (now, rx), (*recent, rx), clock.steps)
        return ClockStep(paused, now, ClockEvent.PAUSED, -since, last)
    return ClockStep(replace(clock, last_rx=rx, segments=recent), t + clock.offset)
