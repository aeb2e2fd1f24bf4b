"""One tick of the rider, without clocks or I/O: source choice, resampling, rules, blends.

The tick asks, at engine time ``now`` (seconds), which *driver* makes the horse:

- ``PROCEDURAL``: the procedural horse, sampled at ``now``;
- ``INPUT``: the active producer's stream (a live engine or a replayed take),
  resampled by :class:`~riderlive.realtime.resample.Resampler`; or a saddle stream
  (``/ws/saddle``), stepped sample by sample through the saddle estimator and read as
  the horse it rebuilds (:class:`~riderlive.realtime.saddle_input.SaddleInput`);
- ``NEUTRAL``: the neutral pose, the rules' answer to a horse standing still (every
  channel zero), with the animator layer applied.

In ``input`` mode the input drives while it is fresh; when it stops (stale or its
producer left) the rider eases to neutral over ``ease_time`` and, with
``fallback_procedural``, the procedural horse resumes ``resume_after`` seconds later
(and gives way again as soon as input is fresh). In ``procedural`` mode the
procedural horse is pinned. Every change of driver, and every takeover by another
producer (or a new stream segment of the same one), blends the rider from its last
output to the new driver's output with a smoothstep, so the output never jumps.

A change of the rule parameters or the animator layer (:meth:`TickCore.set_model`)
blends too, over ``Timing.param_blend``: at the next tick the difference between the
old and the new model on the current horse is added to the new model's output and
fades out with a smoothstep, so the rider keeps moving while it changes.

Whatever drives, each tick's result carries the saddle pose of its horse at the
configured point (:meth:`~riderlive.realtime.edges.UnitEdges.saddle`, computed once per
tick for ``/ws/rider``, takes and devices) and, while a saddle input drives, its estimate.

Units: the core computes in the service length unit, the unit of the input ring it reads
and of the record it writes (the wire); it holds no unit factor. Whatever crosses into
metres or out of them goes through its :class:`~riderlive.realtime.edges.UnitEdges` (the
procedural horse in, the saddle pose at a point in metres, the rider parts on metric
skeletons, a saddle stream's estimator); the rules keep the thesis' units behind their own
adapter (``RiderModel.scale``).

Outputs are finite and bounded: every rider value is clamped to its plausible range
(:mod:`riderlive.ranges`, counted in ``clamped``) before and after the stateful
stages; a stateful stage (smoothing, the blends) that goes non-finite anyway is reset
and the rider eases from neutral over ``ease_time`` (counted in ``resets``, reported
once in ``faults``). A rules output that is itself non-finite touches no state: the
caller repeats its last good frame (``TickLoop._step``).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from riderlive.channels import HORSE_NAMES
from riderlive.horse import ProceduralHorse
from riderlive.realtime.edges import UnitEdges
from riderlive.realtime.layout import InputKind, InputRecord
from riderlive.realtime.resample import Resampler
from riderlive.realtime.saddle_input import NO_ESTIMATE
from riderlive.rules.animator import DamperState, SpringState, damper_start, damper_step, spring_step
from riderlive.rules.engine import RiderModel
from riderlive.rules.parts import PART_OUTPUTS
from riderlive.saddle.pose import SaddlePoint


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
    param_blend: float = 0.5
    """Seconds over which a parameter or animator change blends in."""


@dataclass(frozen=True)
class TickResult:
    """One tick's output: who drove, at which source time, the horse and the rider."""

    driver: Driver
    source_time: float
    producer: int
    horse: list[float]
    rider: list[float]
    saddle: list[float] = field(default_factory=lambda: [0.0] * 6)
    """``channels.SADDLE`` of ``horse`` at the configured point (service length unit, degrees)."""
    estimate: tuple[float, ...] = NO_ESTIMATE
    """The saddle estimate (``record.ESTIMATE_FIELDS``) while a saddle input drives, else NaN."""
    parts: list[float] = field(default_factory=list)
    """The rider parts (``channels.RIDER_PARTS``) of the published rider; empty when the step failed."""


def _smoothstep(x: float) -> float:
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


def _finite(values: Sequence[float]) -> bool:
    return all(map(math.isfinite, values))


Bounds = tuple[Sequence[float], Sequence[float]]
"""Lowest and highest value of each rider channel, in the model's output units."""


class TickCore:
    """The tick's state and its ``step``; every time argument is engine seconds."""

    def __init__(
        self,
        model: RiderModel,
        timing: Timing,
        horse: ProceduralHorse,
        mode: Mode = Mode.INPUT,
        bounds: Bounds | None = None,
        *,
        saddle_point: SaddlePoint | None = None,
    ) -> None:
        self.timing = timing
        self.horse = horse
        self.mode = mode
        self.resampler = Resampler(delay=timing.delay, hold=timing.hold)
        self.saddle_point = saddle_point or SaddlePoint()
        self.edges = UnitEdges(model.scale, self.saddle_point)
        """Where lengths cross to metres and back (built once: the model's scale is the setup's)."""
        self.saddle = self.edges.saddle_input(timing.delay)
        """The saddle producer's stream, while the producer is one (``input_kind``)."""
        self.input_kind = InputKind.HORSE
        self.producer = -1
        self._gone: set[int] = set()
        self.driver = Driver.PROCEDURAL if timing.fallback_procedural or mode is Mode.PROCEDURAL else Driver.NEUTRAL
        self.driver_since = 0.0
        self._blend_from: list[float] | None = None
        self._blend_start = 0.0
        self._blend_duration = 0.0
        self._damper: DamperState | None = None
        self._spring: SpringState | None = None
        self._last_now: float | None = None
        self.last_rider: list[float] | None = None
        """The last output (always finite)."""
        self.model: RiderModel
        self._previous_model: RiderModel | None = None
        self._param_delta: list[float] | None = None
        self._param_start = 0.0
        n = len(model.evaluate([0.0] * len(HORSE_NAMES)))
        self.low, self.high = bounds if bounds is not None else ([-math.inf] * n, [math.inf] * n)
        self.clamped = 0
        """Rider values clamped to their range so far."""
        self.resets = 0
        """Stateful stages reset after going non-finite so far."""
        self._last_reset = -math.inf
        self.faults: list[str] = []
        """Reports of resets not yet taken by the caller (one per reset)."""
        self.full_reach = 0
        """Ticks whose hands were at full reach, the reins outrunning them (``reins.slip`` > 0)."""
        self._no_parts = [0.0] * len(PART_OUTPUTS)
        self.set_model(model)

    def set_model(self, model: RiderModel) -> None:
        """Change presets, weights or the animator layer; blends over ``timing.param_blend``.

        The smoothing filter keeps its state (a new time constant applies from the
        next tick); see the module docstring for the blend.
        """
        if self.last_rider is not None and self.timing.param_blend > 0.0:
            self._previous_model = self._previous_model or self.model
        self.model = model
        self.neutral_horse = [0.0] * len(HORSE_NAMES)
        self.neutral_rider = model.evaluate(self.neutral_horse)
        self.parts = self.edges.rider_parts(model.params)

    def set_mode(self, mode: Mode, now: float) -> None:
        self.mode = mode

    def push_record(self, r: InputRecord) -> bool:
        """:meth:`push_input` of one input ring record."""
        return self.push_input(r.producer, r.t, r.received, r.values, r.kind, rebased=r.rebased)

    def push_input(
        self,
        producer: int,
        t: float,
        received: float,
        values: list[float],
        kind: InputKind = InputKind.HORSE,
        *,
        rebased: bool = False,
    ) -> bool:
        """Buffer one input frame (or step the estimator with one saddle sample); a new
        producer replaces the old one's buffer and estimator.

        Frames of a producer that has gone are ignored: its last frames may still be
        in the ring when the tick learns that it left. ``rebased`` (``ClockStep.rebased``: the
        producer's clock re-anchored at this frame): the clock rate's baseline starts over.
        """
        if producer in self._gone:
            return False
        if producer != self.producer:
            self.resampler.clear()
            self.saddle.clear()
            if self.driver is Driver.INPUT and self.last_rider is not None:
                self._start_blend(received, self.timing.blend_time)
            self.producer = producer
            self.input_kind = kind
        saddle = kind is InputKind.SADDLE
        if rebased:
            (self.saddle.clock if saddle else self.resampler.clock).restart_rate(t)
        return self.saddle.push(t, received, values) if saddle else self.resampler.push(t, received, values)

    def producer_gone(self, producer: int) -> None:
        """The producer disconnected: its stream is stale from now on."""
        self._gone.add(producer)
        if len(self._gone) > 4096:
            self._gone = set(sorted(self._gone)[-1024:])
        if producer == self.producer:
            self.resampler.clear()
            self.saddle.clear()

    def procedural_frame(self, now: float) -> list[float]:
        """The procedural horse at ``now`` in the service unit (it speaks metres)."""
        return self.edges.procedural(self.horse.sample(now))

    def _start_blend(self, now: float, duration: float) -> None:
        self._blend_from = self.last_rider
        self._blend_start = now
        self._blend_duration = duration

    def _choose(self, now: float) -> tuple[Driver, tuple[float, list[float]] | None]:
        if self.mode is Mode.PROCEDURAL:
            return Driver.PROCEDURAL, None
        saddle = self.input_kind is InputKind.SADDLE
        sample = self.saddle.sample(now) if saddle else self.resampler.sample(now)
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
        producer = self.producer if driver is Driver.INPUT else -1
        saddle = self.edges.saddle(horse)
        by_saddle = driver is Driver.INPUT and self.input_kind is InputKind.SADDLE
        estimate = self.saddle.estimate_row(now) if by_saddle else NO_ESTIMATE
        rider = self._rules(driver, horse, now)
        if not _finite(rider):  # stateless so far: no state is touched, the caller repeats its last frame
            return TickResult(driver, source_time, producer, list(horse), rider, saddle, estimate)
        rider = self._smooth(self._bound(rider), now)
        if self._blend_from is not None:
            w = _smoothstep((now - self._blend_start) / self._blend_duration) if self._blend_duration > 0 else 1.0
            if w >= 1.0:
                self._blend_from = None
            else:
                rider = [a + (b - a) * w for a, b in zip(self._blend_from, rider, strict=True)]
        if not _finite(rider):
            self._recover(now, "the blend")
            rider = list(self.neutral_rider)
        rider = self._bound(rider)
        self.last_rider = rider
        return TickResult(
            driver, source_time, producer, list(horse), rider, saddle, estimate, self._parts(horse, rider)
        )

    def _parts(self, horse: Sequence[float], rider: list[float]) -> list[float]:
        """The rider parts of the published rider (finite: a non-finite part falls back to Appendix B's limbs)."""
        try:
            parts = self.parts.evaluate(horse, rider)
        except (ArithmeticError, ValueError):  # math.sin(inf) of a neck channel nobody range-checked
            return list(self._no_parts)
        if not _finite(parts):
            return list(self._no_parts)
        if parts[-1] > 0.0:
            self.full_reach += 1
        return parts

    def _rules(self, driver: Driver, horse: Sequence[float], now: float) -> list[float]:
        """The model's rider for ``horse``, plus what is left of a parameter change's difference."""
        rider = self.neutral_rider if driver is Driver.NEUTRAL else self.model.evaluate(horse)
        if self._previous_model is not None:
            old = self._with_param_delta(self._previous_model.evaluate(horse), now)
            self._previous_model = None
            delta = [a - b for a, b in zip(old, rider, strict=True)]
            self._param_delta, self._param_start = (delta, now) if _finite(delta) else (None, now)
        return self._with_param_delta(rider, now)

    def _with_param_delta(self, rider: list[float], now: float) -> list[float]:
        delta = self._param_delta
        if delta is None:
            return rider
        w = _smoothstep((now - self._param_start) / self.timing.param_blend)
        if w >= 1.0:
            self._param_delta = None
            return rider
        return [r + d * (1.0 - w) for r, d in zip(rider, delta, strict=True)]

    def _bound(self, rider: list[float]) -> list[float]:
        """Clamp each finite value to its channel's range (counted)."""
        low, high = self.low, self.high
        if all(lo <= v <= hi for v, lo, hi in zip(rider, low, high, strict=True)):
            return rider
        out = [min(max(v, lo), hi) for v, lo, hi in zip(rider, low, high, strict=True)]
        self.clamped += sum(a != b for a, b in zip(out, rider, strict=True))
        return out

    def _recover(self, now: float, stage: str) -> None:
        """A stateful stage went non-finite: reset every one, ease from neutral.

        Reported once per episode: resets within ``ease_time`` of the last one are
        counted but not reported again.
        """
        self.resets += 1
        if now - self._last_reset > self.timing.ease_time:
            self.faults.append(f"{stage} went non-finite: reset, easing from neutral")
        self._last_reset = now
        self._damper = None
        self._spring = None
        self._param_delta = None
        self._blend_from = list(self.neutral_rider)
        self._blend_start = now
        self._blend_duration = self.timing.ease_time

    def _smooth(self, rider: list[float], now: float) -> list[float]:
        last = self._last_now
        return self._follow(self._damp(rider, now), now, last)

    def _follow(self, rider: list[float], now: float, last: float | None) -> list[float]:
        """The follow-through spring (``[follow_through]``; 0 Hz: off, no state kept)."""
        follow = self.model.params.follow_through
        if follow.frequency <= 0.0:
            self._spring = None
            return rider
        target = np.asarray(rider, dtype=np.float64)
        if self._spring is None or last is None:
            self._spring = SpringState(target, np.zeros_like(target))
        else:
            with np.errstate(over="ignore", invalid="ignore"):
                self._spring = spring_step(self._spring, target, now - last, follow.frequency, follow.damping_ratio)
            if not (np.isfinite(self._spring.value).all() and np.isfinite(self._spring.velocity).all()):
                self._recover(now, "the follow-through spring")
                self._spring = SpringState(target, np.zeros_like(target))
        out: list[float] = self._spring.value.tolist()
        return out

    def _damp(self, rider: list[float], now: float) -> list[float]:
        tau = self.model.params.smoothing.time_constant
        last, self._last_now = self._last_now, now
        if tau <= 0.0:
            self._damper = None
            return rider
        target = np.asarray(rider, dtype=np.float64)
        if self._damper is None or last is None:
            self._damper = damper_start(target)
        else:
            with np.errstate(over="ignore", invalid="ignore"):
                self._damper = damper_step(self._damper, target, now - last, tau)
            if not (np.isfinite(self._damper.value).all() and np.isfinite(self._damper.velocity).all()):
                self._recover(now, "the smoothing filter")
                self._damper = damper_start(target)
        out: list[float] = self._damper.value.tolist()
        return out
