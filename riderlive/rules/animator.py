"""The animator layer over the rules: per-channel gain and offset, then smoothing.

The thesis keys controls on top of its automation; here that is ``value * gain +
offset`` per rider channel, in output units (after the length scale). An optional
critically damped filter then smooths each channel; its time constant lives in the
preset (``[smoothing]``), 0 switches it off. An optional follow-through (section 9.3's
"loosened up") follows: an underdamped spring per channel, natural frequency and damping
ratio in the preset (``[follow_through]``), 0 Hz switches it off (the thesis).

Each filter's step is written once, as arithmetic that works on floats and arrays
(:func:`damp_exact`, :func:`spring_exact`): :func:`damper_step` and :func:`spring_step`
run it on a frame's channel vector (the live tick), and a whole take runs the same
functions compiled (:mod:`riderlive.rules.filters`, which imports numba only when a take
is filtered).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pydantic

from riderlive.channels import RIDER_NAMES
from riderlive.configfile import ConfigError, StrictModel, read_toml, validate

FloatArray = npt.NDArray[np.float64]


class AnimatorFile(StrictModel):
    """``[offsets]`` and ``[gains]`` tables keyed by rider channel name."""

    offsets: dict[str, float] = pydantic.Field(default_factory=dict)
    gains: dict[str, float] = pydantic.Field(default_factory=dict)


@dataclass(frozen=True)
class AnimatorLayer:
    """Per-channel ``gain`` and ``offset`` on the rider channels (defaults 1 and 0)."""

    offsets: dict[str, float] = field(default_factory=dict)
    gains: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for table in (self.offsets, self.gains):
            for name, value in table.items():
                if name not in RIDER_NAMES:
                    raise KeyError(f"unknown rider channel {name!r}")
                if not math.isfinite(value):
                    raise ValueError(f"{name}: must be a finite number")

    @property
    def is_identity(self) -> bool:
        return all(v == 0.0 for v in self.offsets.values()) and all(v == 1.0 for v in self.gains.values())

    def gain_vector(self) -> FloatArray:
        return np.array([self.gains.get(n, 1.0) for n in RIDER_NAMES])

    def offset_vector(self) -> FloatArray:
        return np.array([self.offsets.get(n, 0.0) for n in RIDER_NAMES])

    @classmethod
    def load(cls, path: str | Path) -> AnimatorLayer:
        """Read a TOML file with ``[offsets]`` and ``[gains]`` tables."""
        source = str(path)
        model = validate(AnimatorFile, read_toml(path), source)
        for table_name, table in (("offsets", model.offsets), ("gains", model.gains)):
            for name in table:
                if name not in RIDER_NAMES:
                    raise ConfigError(source, f"{table_name}.{name}", "unknown rider channel")
        return cls(offsets=dict(model.offsets), gains=dict(model.gains))


@dataclass(frozen=True, slots=True)
class DamperState:
    """Position and velocity of each channel's critically damped follower."""

    value: FloatArray
    velocity: FloatArray


def damper_start(target: FloatArray) -> DamperState:
    """A follower at rest on ``target``."""
    return DamperState(value=np.array(target, dtype=np.float64), velocity=np.zeros_like(target, dtype=np.float64))


def damper_step(state: DamperState, target: FloatArray, dt: float, time_constant: float) -> DamperState:
    """Advance a critically damped follower by ``dt`` seconds toward ``target``.

    The exact solution of ``x'' = w^2 (target - x) - 2 w x'`` with the target held
    over the step (``w = 1 / time_constant``), so it is stable at any ``dt`` and a
    sequence of steps does not depend on how time is cut.
    """
    if time_constant <= 0.0 or dt <= 0.0:
        return DamperState(value=np.array(target, dtype=np.float64), velocity=state.velocity * 0.0)
    omega = 1.0 / time_constant
    value, velocity = damp_exact(state.value, state.velocity, target, dt, omega, math.exp(-omega * dt))
    return DamperState(value=value, velocity=velocity)


def damp_exact(  # noqa: PLR0917
    value: Any, velocity: Any, target: Any, dt: float, omega: float, decay: float
) -> tuple[Any, Any]:
    """One follower step (floats or arrays): ``(value, velocity)`` after ``dt`` s; ``decay = exp(-omega dt)``."""
    delta = value - target
    drive = velocity + omega * delta
    return target + (delta + drive * dt) * decay, (velocity - omega * drive * dt) * decay


@dataclass(frozen=True, slots=True)
class SpringState:
    """Position and velocity of each channel's underdamped follower (the follow-through)."""

    value: FloatArray
    velocity: FloatArray


def spring_step(state: SpringState, target: FloatArray, dt: float, frequency: float, damping: float) -> SpringState:
    """Advance an underdamped spring by ``dt`` seconds toward ``target`` (held over the step).

    The exact solution of ``x'' = w^2 (target - x) - 2 z w x'`` with ``w = 2 pi frequency``
    (Hz) and ``z = damping`` in (0, 1): stable at any ``dt``, and a sequence of steps does
    not depend on how time is cut. A step input overshoots by ``exp(-pi z / sqrt(1 - z^2))``.
    ``frequency`` or ``dt`` <= 0: the spring sits on the target, at rest.
    """
    if frequency <= 0.0 or dt <= 0.0:
        return SpringState(value=np.array(target, dtype=np.float64), velocity=state.velocity * 0.0)
    omega, decay_rate, omega_d = spring_rates(frequency, damping)
    decay = math.exp(-decay_rate * dt)
    c, s = math.cos(omega_d * dt), math.sin(omega_d * dt)
    value, velocity = spring_exact(state.value, state.velocity, target, omega, decay_rate, omega_d, decay, c, s)
    return SpringState(value=value, velocity=velocity)


def spring_rates(frequency: float, damping: float) -> tuple[float, float, float]:
    """(natural angular frequency, decay rate, damped angular frequency), rad/s and 1/s."""
    omega = 2.0 * math.pi * frequency
    return omega, damping * omega, omega * math.sqrt(1.0 - damping * damping)


def spring_exact(  # noqa: PLR0917
    value: Any,
    velocity: Any,
    target: Any,
    omega: float,
    decay_rate: float,
    omega_d: float,
    decay: float,
    c: float,
    s: float,
) -> tuple[Any, Any]:
    """One spring step (floats or arrays): ``decay = exp(-decay_rate dt)``, ``c, s = cos, sin(omega_d dt)``."""
    delta = value - target
    b = (velocity + decay_rate * delta) / omega_d
    return (
        target + decay * (delta * c + b * s),
        decay * (velocity * c - (decay_rate * velocity + omega * omega * delta) / omega_d * s),
    )
