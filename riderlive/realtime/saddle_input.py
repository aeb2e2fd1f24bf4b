"""The saddle in the tick: a saddle stream driving the rider, and the saddle pose of every tick.

Pure (no clocks, no I/O); every time argument is seconds, engine or producer as named.

- :class:`SaddleInput`: the driving saddle producer's stream. Each received sample is
  stepped through the estimator (:func:`riderlive.saddle.step`) in source-time order,
  so a 1000 Hz stream is seen sample by sample, not once per tick. At the tick's time
  the rebuilt horse frame (:func:`riderlive.saddle.horse_frame`) is read at the
  producer's time that corresponds to it (the clock mapping of the least-delayed
  sample, as the resampler's, but without its ``input.delay``: the estimator
  extrapolates the hooves itself and holds the measured pose). After the last sample
  the estimator runs on for ``Model.hold`` (0.5 s) and eases to standing over
  ``Model.ease`` (0.25 s); after that the stream is *stale* (counted) and the tick
  eases the rider to neutral as for a horse stream that stops.
- :func:`saddle_pose`: ``channels.SADDLE`` of any horse frame, in the service's units
  (what ``/ws/rider`` publishes and takes record, whatever drives).
- :func:`estimate_row`: the estimate as the output record carries it (codes and numbers).

The input ring carries lengths in the service unit (``length_scale / 25`` metres); the
estimator speaks metres and degrees, so lengths are converted on the way in and out.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

from riderlive.channels import HORSE, Kind
from riderlive.horse import DEFAULT_SCALE
from riderlive.horse.gaits import Gait
from riderlive.saddle import Lock, Model, SaddlePoint, State, estimate, horse_frame, saddle_from_horse, step
from riderlive.saddle.pose import BEND_COLUMN, SCALAR, TRUNK_COLUMNS, saddle_from_trunk

LOCKS: tuple[str, ...] = tuple(lock.value for lock in Lock)
"""Lock states by their code in a record (``no_signal`` 0, ``still`` 1, ``searching`` 2, ``locked`` 3)."""
GAITS: tuple[str, ...] = tuple(gait.value for gait in Gait)
"""Gaits by their code in a record (``walk`` 0 ... ``halt`` 4)."""
NO_ESTIMATE: tuple[float, ...] = (math.nan,) * 5
"""The estimate of a record no saddle input drives."""
COUNTERS: tuple[str, ...] = ("samples", "missing", "empty", "gaps", "glitches", "rebases", "locks", "losses")
"""Estimator counters summed over every saddle stream the tick has seen (``saddle_<name>``)."""
_HORSE_LENGTHS = tuple(i for i, c in enumerate(HORSE) if c.kind is Kind.TRANSLATION)
_OFFSETS = 256
"""Samples whose clock offset the mapping takes the least of (as the resampler's buffer)."""


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


@dataclass
class SaddleInput:
    """The driving saddle stream in the tick: the estimator's state and the clock mapping."""

    model: Model
    to_metres: float = 1.0
    """Service length unit -> metres."""

    def __post_init__(self) -> None:
        self.state = State()
        self.offsets: deque[float] = deque(maxlen=_OFFSETS)
        self.offset: float | None = None
        self.stale = False
        self.finished = dict.fromkeys(COUNTERS, 0)
        """Counters of the streams before the current one."""
        self.stale_episodes = 0
        """Times a driving saddle stream went stale (the rider eased to neutral)."""

    def clear(self) -> None:
        """A new stream (another producer, a new segment, a producer gone): start afresh."""
        for name, value in self._current().items():
            self.finished[name] += value
        self.state = State()
        self.offsets.clear()
        self.offset = None
        self.stale = False

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
        if not t > self.state.t:
            return False
        gain = self.to_metres
        sample = [v * gain for v in values[:3]] + [float(v) for v in values[3:6]] if gain != 1.0 else values[:6]
        self.state = step(self.model, self.state, t, sample)
        offset = received - t
        if len(self.offsets) == self.offsets.maxlen and self.offsets[0] == self.offset:
            self.offsets.append(offset)
            self.offset = min(self.offsets)
        else:
            self.offsets.append(offset)
            self.offset = offset if self.offset is None else min(self.offset, offset)
        self.stale = False
        return True

    def source_time(self, now: float) -> float | None:
        """The producer time shown at engine time ``now`` (never before the last sample)."""
        if self.offset is None:
            return None
        return max(now - self.offset, self.state.t)

    def sample(self, now: float) -> tuple[float, list[float]] | None:
        """``(producer time, horse frame in service units)`` at engine time ``now``, or None when stale."""
        query = self.source_time(now)
        if query is None:
            return None
        if query - self.state.t > self.model.hold + self.model.ease:
            if not self.stale:
                self.stale = True
                self.stale_episodes += 1
            return None
        frame = horse_frame(self.model, self.state, query)
        if self.to_metres != 1.0:
            for i in _HORSE_LENGTHS:
                frame[i] /= self.to_metres
        return query, frame

    def estimate_row(self, now: float) -> tuple[float, ...]:
        query = self.source_time(now)
        return NO_ESTIMATE if query is None else estimate_row(self.state, query)


def make_saddle_input(length_scale: float, point: SaddlePoint) -> SaddleInput:
    """The tick's saddle input for a service speaking ``length_scale`` rig units per its length unit."""
    return SaddleInput(Model(point=point), length_scale / DEFAULT_SCALE)
