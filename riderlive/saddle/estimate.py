"""What the saddle estimator publishes: :class:`Estimate`, a view of its :class:`~riderlive.saddle.estimator.State`.

Gait, stride frequency (Hz), phase (strides, 0-1), speed (m/s), lock, the match's score,
the age of the last sample (s) and the counters; the tick's status, the output record's
saddle estimate (``realtime/saddle_input.py``) and ``riderlive saddle`` read it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from riderlive.horse.gaits import Gait
from riderlive.saddle.estimator import Counters, Lock, State


@dataclass(frozen=True, slots=True)
class Estimate:
    """What the estimator publishes.

    Gait, stride frequency (Hz), phase (0-1), speed (m/s), lock, the match's score,
    ``age`` (s since the last sample, None before the first: a stopped stream shows
    here, and the rebuilt frame eases to standing after ``Model.hold``) and the counters.
    """

    gait: str | None
    stride_hz: float
    phase: float
    speed: float
    lock: str
    score: float
    age: float | None
    counters: dict[str, int]

    def as_dict(self) -> dict[str, Any]:
        return {
            "gait": self.gait,
            "stride_hz": self.stride_hz,
            "phase": self.phase,
            "speed": self.speed,
            "lock": self.lock,
            "score": self.score,
            "age": self.age,
            "counters": self.counters,
        }


def estimate(state: State, t: float | None = None) -> Estimate:
    """The estimator's state as data, at ``t`` (default: the last sample's time)."""
    t = state.t if t is None else t
    tr = state.tracking
    track = tr.track if tr.lock is Lock.LOCKED else None
    counters = {"samples": state.samples, "missing": state.missing}
    counters.update({name: getattr(tr.counters, name) for name in Counters.__slots__})
    return Estimate(
        gait=track.gait.value if track else (Gait.HALT.value if tr.lock is Lock.STILL else None),
        stride_hz=track.frequency if track else 0.0,
        phase=track.phase(t) % 1.0 if track else 0.0,
        speed=track.speed if track else 0.0,
        lock=tr.lock.value,
        score=tr.fit.score if tr.fit else 0.0,
        age=t - state.t if state.t > -math.inf else None,
        counters=counters,
    )
