"""Resampling a live input stream onto the tick (pure: no clocks, no I/O).

Frames arrive with the producer's own time ``t`` (seconds, any origin) and the
receive time (engine seconds). The producer's clock is mapped onto the engine's by
the smallest ``receive - t`` seen in the buffer (the least-delayed frame), so the
mapping follows the producer's clock but not its network jitter. The tick then
reads the stream ``delay`` seconds in the past:

- between two frames: linear interpolation;
- before the oldest buffered frame: the oldest frame;
- after the newest frame: the newest frame held, for at most ``hold`` seconds of
  source time; beyond that the stream is stale (None). Nothing is extrapolated.
"""

from __future__ import annotations

import bisect
from collections import deque
from dataclasses import dataclass, field


@dataclass
class Resampler:
    """The buffered frames of one producer."""

    delay: float = 0.01
    hold: float = 0.25
    capacity: int = 512
    times: deque[float] = field(default_factory=deque)
    frames: deque[list[float]] = field(default_factory=deque)
    offsets: deque[float] = field(default_factory=deque)
    offset: float | None = None
    """Engine time minus producer time of the least-delayed buffered frame."""

    def clear(self) -> None:
        self.times.clear()
        self.frames.clear()
        self.offsets.clear()
        self.offset = None

    def push(self, t: float, received: float, values: list[float]) -> bool:
        """Add a frame; a frame not newer than the newest is dropped (returns False)."""
        if self.times and t <= self.times[-1]:
            return False
        self.times.append(t)
        self.frames.append(values)
        offset = received - t
        self.offsets.append(offset)
        if self.offset is None or offset < self.offset:
            self.offset = offset
        if len(self.times) > self.capacity:
            self.times.popleft()
            self.frames.popleft()
            if self.offsets.popleft() == self.offset:
                self.offset = min(self.offsets)
        return True

    def source_time(self, now: float) -> float | None:
        """The producer time the tick at engine time ``now`` should show."""
        if self.offset is None:
            return None
        return now - self.offset - self.delay

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
