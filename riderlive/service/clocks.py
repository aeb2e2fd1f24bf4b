"""A producer's clock against the service's: jumps, backward steps, a clock that stands
still (pure: state in, state out; docs/protocol.md, "Clocks that jump").

Each frame brings the producer's time ``t`` and its receive time ``rx`` (engine
seconds). :func:`clock_step` decides the time the tick is given for it and whether the
stream starts a new *segment* (a fresh clock mapping in the tick, a blend, a
``segment`` message to the producer):

- **jump** (``clock_forward`` / ``clock_backward``): between two frames the producer's
  clock moved more than ``jump_s`` more or less than the service's;
- **step back** (``clock_backward``): ``t`` went back by more than :data:`STEP_S`
  but less than a jump (a clock stepped by NTP, a game's time scale reset). Without a
  new segment the tick would drop every frame until ``t`` passed its old newest, and
  its clock mapping would stay ``step`` off for seconds;
- **paused** (``clock_paused``): frames keep coming but ``t`` has not moved for
  ``pause_s`` (a paused game): the service's clock stands in for the producer's (``t``
  of the pause plus the service seconds since), so the producer keeps driving with its
  frames as they come;
- **resumed** (``clock_resumed``): the clock moves again after a pause: its own ``t``
  again, in a new segment.

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
    standin: tuple[float, float] | None = None
    """While paused: (``t``, ``rx``) from which the service's clock stands in."""
    segments: tuple[float, ...] = ()
    """Receive times of the step and pause segments of the last second."""


@dataclass(frozen=True)
class ClockStep:
    clock: ProducerClock
    t: float
    """The time the tick is given for this frame."""
    event: ClockEvent | None = None
    jump: float = 0.0
    """How far the producer's clock moved beyond (or short of) the service's, s."""
    previous_t: float | None = None


def clock_step(clock: ProducerClock, t: float, rx: float, jump_s: float, pause_s: float) -> ClockStep:
    """One frame's time; see the module docstring."""
    last = clock.newest_t
    if last is None:
        return ClockStep(ProducerClock(t, rx, rx, None, clock.segments), t)
    recent = tuple(s for s in clock.segments if rx - s < 1.0)
    may_segment = len(recent) < MAX_SEGMENTS_PER_S
    if clock.standin is not None:
        t0, rx0 = clock.standin
        if t > last:
            drift = (t - last) - (rx - clock.moved_rx)
            return ClockStep(ProducerClock(t, rx, rx, None, recent), t, ClockEvent.RESUMED, drift, last)
        if t < last - STEP_S and may_segment:
            drift = t - last
            return ClockStep(ProducerClock(t, rx, rx, None, (*recent, rx)), t, ClockEvent.BACKWARD, drift, last)
        return ClockStep(replace(clock, last_rx=rx, segments=recent), t0 + (rx - rx0))
    drift = (t - last) - (rx - clock.last_rx)
    if abs(drift) > jump_s:
        event = ClockEvent.FORWARD if drift > 0 else ClockEvent.BACKWARD
        return ClockStep(ProducerClock(t, rx, rx, None, recent), t, event, drift, last)
    if t > last:
        return ClockStep(ProducerClock(t, rx, rx, None, recent), t)
    if t < last - STEP_S and may_segment:
        return ClockStep(ProducerClock(t, rx, rx, None, (*recent, rx)), t, ClockEvent.BACKWARD, t - last, last)
    still = rx - clock.moved_rx
    if still >= pause_s and may_segment:
        standin = ProducerClock(last, rx, clock.moved_rx, (last, rx), (*recent, rx))
        return ClockStep(standin, last, ClockEvent.PAUSED, -still, last)
    return ClockStep(replace(clock, last_rx=rx, segments=recent), t)
