"""The stride oscillator and the eased weights of the estimator's output (pure values)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from riderlive.horse.gaits import Gait


@dataclass(frozen=True, slots=True)
class Track:
    """The stride oscillator: ``phase(t) = phase0 + rate * (t - t0)`` (strides)."""

    gait: Gait
    phase0: float
    t0: float
    rate: float  # the oscillator's Hz (frequency plus the phase correction)
    frequency: float  # the estimated stride frequency (Hz)
    speed: float  # m/s, from the gait's frequency law
    distance0: float = 0.0  # m travelled by t0

    def phase(self, t: float) -> float:
        return self.phase0 + self.rate * (t - self.t0)

    def distance(self, t: float) -> float:
        return self.distance0 + self.speed * (t - self.t0)


@dataclass(frozen=True, slots=True)
class Ease:
    """A weight easing (smoothstep) from ``start`` to ``target`` from ``t0`` over ``duration`` s."""

    start: float = 0.0
    target: float = 0.0
    t0: float = -math.inf
    duration: float = 1.0

    def at(self, t: float) -> float:
        u = (t - self.t0) / self.duration
        if u >= 1.0:
            return self.target
        u = max(u, 0.0)
        return self.start + (self.target - self.start) * u * u * (3.0 - 2.0 * u)

    def toward(self, target: float, t: float, duration: float) -> Ease:
        if target == self.target:
            return self
        return Ease(self.at(t), target, t, duration)
