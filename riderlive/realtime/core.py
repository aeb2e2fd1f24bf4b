"""One tick of the rider, without clocks or I/O: source choice, resampling, rules, blends.

The tick asks, at engine time ``now`` (seconds), which *driver* makes the horse:

- ``PROCEDURAL``: the procedural horse, sampled at ``now``;
- ``INPUT``: the active producer's stream (a live engine or a replayed take),
  resampled by :class:`~riderlive.realtime.resample.Resampler`;
- ``NEUTRAL``: the neutral pose, the rules' answer to a horse standing still (every
  channel zero), with the animator layer applied.

In ``input`` mode the input drives while it is fresh; when it stops (stale or its
producer left) the rider eases to neutral over ``ease_time`` and, with
``fallback_procedural``, the procedural horse resumes ``resume_after`` seconds later
(and gives way again as soon as input is fresh). In ``procedural`` mode the
procedural horse is pinned. Every change of driver, and every takeover by another
producer, blends the rider from its last output to the new driver's output with a
smoothstep, so the output never jumps.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from riderlive.channels import HORSE, HORSE_NAMES, Kind
from riderlive.horse import DEFAULT_SCALE, ProceduralHorse
from riderlive.realtime.resample import Resampler
from riderlive.rules.animator import DamperState, damper_start, damper_step
from riderlive.rules.engine import RiderModel


class Driver(enum.IntEnum):
    """What produced a tick's horse frame (published as its name, lower case)."""

    PROCEDURAL = 0
    INPUT = 1
    NEUTRAL = 2


class Mode(enum.Enum):
    """The selected source: ``input`` (live producers or a replay) or pinned ``procedural``."""

    INPUT = "input"
    PROCEDURAL = "procedural"


@dataclass(frozen=True)
class Timing:
    """Resampling and transition times, in seconds."""

    delay: float = 0.01
    hold: float = 0.25
    ease_time: float = 1.0
    blend_time: float = 0.5
    resume_after: float = 2.0
    fallback_procedural: bool = True


@dataclass(frozen=True)
class TickResult:
    """One tick's output: who drove, at which source time, the horse and the rider."""

    driver: Driver
    source_time: float
    producer: int
    horse: list[float]
    rider: list[float]


_TRANSLATION = tuple(i for i, c in enumerate(HORSE) if c.kind is Kind.TRANSLATION)


def _smoothstep(x: float) -> float:
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


class TickCore:
    """The tick's state and its ``step``; every time argument is engine seconds."""

    def __init__(self, model: RiderModel, timing: Timing, horse: ProceduralHorse, mode: Mode = Mode.INPUT) -> None:
        self.timing = timing
        self.horse = horse
        self.mode = mode
        self.resampler = Resampler(delay=timing.delay, hold=timing.hold)
        self.producer = -1
        self._gone: set[int] = set()
        self.driver = Driver.PROCEDURAL if timing.fallback_procedural or mode is Mode.PROCEDURAL else Driver.NEUTRAL
        self.driver_since = 0.0
        self._blend_from: list[float] | None = None
        self._blend_start = 0.0
        self._blend_duration = 0.0
        self._damper: DamperState | None = None
        self._last_now: float | None = None
        self.last_rider: list[float] | None = None
        self.set_model(model)

    def set_model(self, model: RiderModel) -> None:
        """Change presets, weights or the animator layer; blends like a takeover."""
        self.model = model
        self.neutral_horse = [0.0] * len(HORSE_NAMES)
        self.neutral_rider = model.evaluate(self.neutral_horse)
        # The procedural horse speaks metres; inputs are in the model's length unit.
        self._procedural_gain = DEFAULT_SCALE / model.scale
        self._damper = None

    def set_mode(self, mode: Mode, now: float) -> None:
        self.mode = mode

    def push_input(self, producer: int, t: float, received: float, values: list[float]) -> bool:
        """Buffer one input frame; a new producer replaces the old one's buffer.

        Frames of a producer that has gone are ignored: its last frames may still be
        in the ring when the tick learns that it left.
        """
        if producer in self._gone:
            return False
        if producer != self.producer:
            self.resampler.clear()
            if self.driver is Driver.INPUT and self.last_rider is not None:
                self._start_blend(received, self.timing.blend_time)
            self.producer = producer
        return self.resampler.push(t, received, values)

    def producer_gone(self, producer: int) -> None:
        """The producer disconnected: its stream is stale from now on."""
        self._gone.add(producer)
        if len(self._gone) > 4096:
            self._gone = set(sorted(self._gone)[-1024:])
        if producer == self.producer:
            self.resampler.clear()

    def procedural_frame(self, now: float) -> list[float]:
        frame = self.horse.sample(now)
        gain = self._procedural_gain
        if gain != 1.0:
            for i in _TRANSLATION:
                frame[i] *= gain
        return frame

    def _start_blend(self, now: float, duration: float) -> None:
        self._blend_from = self.last_rider
        self._blend_start = now
        self._blend_duration = duration

    def _choose(self, now: float) -> tuple[Driver, tuple[float, list[float]] | None]:
        if self.mode is Mode.PROCEDURAL:
            return Driver.PROCEDURAL, None
        sample = self.resampler.sample(now)
        if sample is not None:
            return Driver.INPUT, sample
        if self.driver is Driver.PROCEDURAL:
            return (Driver.PROCEDURAL if self.timing.fallback_procedural else Driver.NEUTRAL), None
        if (
            self.driver is Driver.NEUTRAL
            and self.timing.fallback_procedural
            and now - self.driver_since >= self.timing.ease_time + self.timing.resume_after
        ):
            return Driver.PROCEDURAL, None
        return Driver.NEUTRAL, None

    def step(self, now: float) -> TickResult:
        """The rider at engine time ``now`` (non-decreasing between calls)."""
        driver, sample = self._choose(now)
        if driver is not self.driver:
            duration = self.timing.ease_time if driver is Driver.NEUTRAL else self.timing.blend_time
            if self.last_rider is not None:
                self._start_blend(now, duration)
            self.driver = driver
            self.driver_since = now
        if driver is Driver.INPUT:
            assert sample is not None
            source_time, horse = sample
        elif driver is Driver.PROCEDURAL:
            source_time, horse = now, self.procedural_frame(now)
        else:
            source_time, horse = now, self.neutral_horse
        rider = self.neutral_rider if driver is Driver.NEUTRAL else self.model.evaluate(horse)
        rider = self._smooth(rider, now)
        if self._blend_from is not None:
            w = _smoothstep((now - self._blend_start) / self._blend_duration) if self._blend_duration > 0 else 1.0
            if w >= 1.0:
                self._blend_from = None
            else:
                rider = [a + (b - a) * w for a, b in zip(self._blend_from, rider, strict=True)]
        self.last_rider = rider
        producer = self.producer if driver is Driver.INPUT else -1
        return TickResult(driver, source_time, producer, list(horse), rider)

    def _smooth(self, rider: Sequence[float], now: float) -> list[float]:
        tau = self.model.params.smoothing.time_constant
        last, self._last_now = self._last_now, now
        if tau <= 0.0:
            return list(rider)
        target = np.asarray(rider, dtype=np.float64)
        if self._damper is None or last is None:
            self._damper = damper_start(target)
        else:
            self._damper = damper_step(self._damper, target, now - last, tau)
        out: list[float] = self._damper.value.tolist()
        return out
