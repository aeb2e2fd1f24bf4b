"""Inputs at any instant, and a fixed-step accumulator that makes results independent of the tick rate.

The physics steps at a fixed rate (``PhysicsConfig.rate``, 240 Hz by default). At each
internal step it asks a :class:`Source` for the horse (and rider) frame at that step's
own time ``k / rate``; the caller only says how far to go (:meth:`FixedStepper.advance_to`).
So a take ticked at 30, 60, 120 or 144 Hz runs the very same steps on the very same
inputs, and the states at common times are bit-identical.

Sources: :class:`TakeSource` interpolates a recorded take linearly (holding the ends);
:class:`LiveSource` wraps a live horse (the ``sample(t)`` contract of
:mod:`riderlive.horse`) and optionally evaluates the rider rules on each frame. A
network feed can be wrapped in a :class:`TakeSource` over the frames received so far.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Generic, Protocol, TypeVar

import numpy as np
import numpy.typing as npt

from riderlive.channels import HORSE

FloatArray = npt.NDArray[np.float64]
StateT = TypeVar("StateT")


@dataclass(frozen=True, eq=False)
class Drive:
    """What moves the strands at one instant: a horse frame (``channels.HORSE`` order) and a rider frame or None."""

    horse: FloatArray
    rider: FloatArray | None = None


class Source(Protocol):
    def __call__(self, t: float) -> Drive: ...


class HorseSampler(Protocol):
    def sample(self, t: float) -> list[float]: ...


class RiderRules(Protocol):
    def evaluate(self, horse: list[float]) -> list[float]: ...


class TakeSource:
    """A recorded take: ``times`` (N,) increasing, ``horse`` (N, len(HORSE)), ``rider`` (N, R) or None."""

    def __init__(self, times: FloatArray, horse: FloatArray, rider: FloatArray | None = None) -> None:
        times = np.asarray(times, dtype=np.float64)
        if times.ndim != 1 or len(times) == 0 or np.any(np.diff(times) <= 0.0):
            raise ValueError("times must be a non-empty, strictly increasing 1-D array")
        if horse.shape != (len(times), len(HORSE)):
            raise ValueError(f"horse must be ({len(times)}, {len(HORSE)}), got {horse.shape}")
        self.times, self.horse, self.rider = times, np.asarray(horse, dtype=np.float64), rider

    def __call__(self, t: float) -> Drive:
        i = int(np.searchsorted(self.times, t, side="right")) - 1
        if i < 0:
            return Drive(self.horse[0], None if self.rider is None else self.rider[0])
        if i >= len(self.times) - 1:
            return Drive(self.horse[-1], None if self.rider is None else self.rider[-1])
        f = (t - self.times[i]) / (self.times[i + 1] - self.times[i])
        horse = self.horse[i] + f * (self.horse[i + 1] - self.horse[i])
        rider = None if self.rider is None else self.rider[i] + f * (self.rider[i + 1] - self.rider[i])
        return Drive(horse, rider)


class LiveSource:
    """A live horse (``sample(t)``), with the rider rules evaluated per frame when given."""

    def __init__(self, horse: HorseSampler, rules: RiderRules | None = None) -> None:
        self.horse, self.rules = horse, rules

    def __call__(self, t: float) -> Drive:
        frame = self.horse.sample(t)
        rider = None if self.rules is None else np.asarray(self.rules.evaluate(frame), dtype=np.float64)
        return Drive(np.asarray(frame, dtype=np.float64), rider)


class FixedStepper(Generic[StateT]):
    """Runs ``step(state, drive)`` at a fixed ``rate`` up to any requested time (the accumulator).

    Step ``k`` (1, 2, ...) ends at time ``start + k / rate`` and sees ``source`` at
    that time. Time is counted in whole steps, not accumulated floats, so no rounding
    drifts between tick rates. Safe behaviour on bad input: a drive with NaN or inf is
    replaced by the last good one (counted in ``bad_inputs``); a jump of more than
    ``max_catch_up`` steps (a stalled caller) skips the excess time instead of
    stepping through it all (counted in ``skipped_steps``), so one late tick cannot
    stall the loop.
    """

    def __init__(
        self,
        step: Callable[[StateT, Drive], StateT],
        state: StateT,
        rate: float,
        start: float = 0.0,
        max_catch_up: int | None = None,
    ) -> None:
        if not (math.isfinite(rate) and rate > 0.0):
            raise ValueError(f"rate must be a finite number > 0, got {rate!r}")
        self._step, self.state, self.rate, self.start = step, state, rate, start
        self.max_catch_up = max_catch_up
        self.steps = 0
        self.bad_inputs = 0
        self.skipped_steps = 0
        self._last_good: Drive | None = None

    @property
    def time(self) -> float:
        """The time the current state belongs to, seconds."""
        return self.start + self.steps / self.rate

    def advance_to(self, t: float, source: Source) -> int:
        """Take every step that ends at or before ``t``; returns how many were taken."""
        due = math.floor((t - self.start) * self.rate + 1e-6)
        if self.max_catch_up is not None and due - self.steps > self.max_catch_up:
            skip = due - self.steps - self.max_catch_up
            self.skipped_steps += skip
            self.start += skip / self.rate
            due = math.floor((t - self.start) * self.rate + 1e-6)
        taken = 0
        while self.steps < due:
            self.steps += 1
            drive = source(self.start + self.steps / self.rate)
            if not _finite(drive):
                self.bad_inputs += 1
                if self._last_good is None:
                    raise ValueError("the first drive has non-finite values: nothing to hold")
                drive = self._last_good
            self._last_good = drive
            self.state = self._step(self.state, drive)
            taken += 1
        return taken


def _finite(drive: Drive) -> bool:
    return bool(np.isfinite(drive.horse).all() and (drive.rider is None or np.isfinite(drive.rider).all()))
