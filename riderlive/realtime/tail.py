"""The horse's tail and the rider's braid in the tick: strand physics driven by the tick's own frames.

:class:`TickPhysics` wraps :class:`riderlive.physics.skinned.SkinnedModel` (compiled
kernels) and a :class:`riderlive.physics.drive.FixedStepper`. Each tick hands it the
horse and rider frames the tick produced at engine time ``now``; the stepper takes
every internal step (``PhysicsConfig.rate``, 240 Hz) that ends by ``now``, each one
seeing the tick frames interpolated linearly to its own time (:class:`TickFrames`:
exactly what :class:`~riderlive.physics.drive.TakeSource` does on a recorded take,
so an offline run on the take gives the same values). Publishing stays outside the
step and is done only when a step was taken.

Units: the tick's frames are in service length units; the physics speaks metres. Both
crossings are the tick's :class:`~riderlive.realtime.edges.UnitEdges` (``strands_in``: the
frames' lengths to metres; ``strands_out``: the published positions and ``fan`` back to the
service unit); nothing here converts. Pure apart from the kernels' compile-on-first-use:
:meth:`TickPhysics.warm` makes that happen before the loop starts.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from riderlive.channels import Kind, lookup
from riderlive.physics.config import load_physics
from riderlive.physics.drive import Drive, FixedStepper
from riderlive.physics.outputs import channel_names, publish
from riderlive.physics.skinned import SkinnedModel, SkinnedState
from riderlive.realtime.edges import UnitEdges

FloatArray = npt.NDArray[np.float64]
MAX_CATCH_UP = 48
"""Internal steps one tick may take (0.2 s at 240 Hz); a longer stall skips the excess time."""


def physics_channels(file: str | Path | None = None) -> tuple[str, ...]:
    """The ``tail_NN.*`` / ``braid_NN.*`` channels the tick publishes for a physics config."""
    return channel_names(SkinnedModel.build(load_physics(file)))


class TickFrames:
    """The source between two tick frames: linear interpolation, held at the ends (``TakeSource``'s arithmetic)."""

    def __init__(self) -> None:
        self.t0 = self.t1 = 0.0
        self.a: Drive | None = None
        self.b: Drive | None = None

    def push(self, t: float, drive: Drive) -> None:
        self.t0, self.a = self.t1, self.b
        self.t1, self.b = t, drive

    def __call__(self, t: float) -> Drive:
        a, b = self.a, self.b
        assert b is not None
        if a is None or t >= self.t1:
            return b
        if t < self.t0:
            return a
        f = (t - self.t0) / (self.t1 - self.t0)
        assert a.rider is not None and b.rider is not None
        with np.errstate(invalid="ignore", over="ignore"):  # a non-finite drive is the stepper's to hold
            return Drive(a.horse + f * (b.horse - a.horse), a.rider + f * (b.rider - a.rider))


@dataclass(frozen=True)
class TailState:
    """What a tick's strands are now, for the generation that takes over (``realtime/handover.py``):
    the stepper's state and clock (physics seconds since ``start``, engine seconds), the two
    tick frames it interpolates between, and the counts."""

    start: float
    stepper_start: float
    steps: int
    state: SkinnedState
    last_good: Drive | None
    frames: tuple[float, float, Drive | None, Drive | None]
    values: tuple[float, ...]
    errors: int
    skipped_steps: int
    bad_inputs: int


class TickPhysics:
    """The skinned tail and braid as the tick runs them; :meth:`tick` once per tick."""

    def __init__(self, file: str | Path | None, edges: UnitEdges) -> None:
        self.config = load_physics(file)
        self.model = SkinnedModel.build(self.config)
        self.names = channel_names(self.model)
        self.edges = edges
        self._lengths = np.array([lookup(n).kind is Kind.TRANSLATION for n in self.names])
        self.frames = TickFrames()
        self.stepper: FixedStepper[SkinnedState] | None = None
        self.start = math.nan
        """Engine time of the first tick the physics saw (its state starts from rest there);
        the physics' own clock is ``now - start``."""
        self.values: list[float] = []
        self.errors = 0
        self._skipped_before = 0
        """Steps skipped by steppers replaced at a restart."""

    def drive(self, horse: Sequence[float], rider: Sequence[float]) -> Drive:
        """A tick's frames in the physics' units (metres, degrees)."""
        return Drive(*self.edges.strands_in(horse, rider))

    def warm(self, horse: Sequence[float], rider: Sequence[float]) -> None:
        """Compile (or load) the kernels and run publishing once, so no tick pays for it."""
        drive = self.drive(horse, rider)
        state = self.model.initial(drive)
        for _ in range(3):
            state = self.model.step(state, drive)
        self._publish(state)

    def _publish(self, state: SkinnedState) -> list[float]:
        return self.edges.strands_out(publish(self.model, state), self._lengths)

    def restart(self, now: float, drive: Drive) -> None:
        """Start from rest at ``now``: the bones along the dock, as at the first tick."""
        if self.stepper is not None:
            self._skipped_before += self.stepper.skipped_steps
        self.start = now
        self.frames = TickFrames()
        self.frames.push(0.0, drive)
        self.stepper = FixedStepper(
            self.model.step, self.model.initial(drive), self.config.rate, start=0.0, max_catch_up=MAX_CATCH_UP
        )

    def tick(self, now: float, horse: Sequence[float], rider: Sequence[float]) -> list[float]:
        """The channels at engine time ``now`` (seconds, non-decreasing) for this tick's frames.

        The tick's frames are finite (the tick guards them); a step that raises or
        gives a non-finite value restarts the strands from rest at this frame
        (counted in ``errors``), so the published values are always finite.
        """
        drive = self.drive(horse, rider)
        if self.stepper is None:
            self.restart(now, drive)
            assert self.stepper is not None
            self.values = self._publish(self.stepper.state)
            return self.values
        t = now - self.start  # as a take recorded from this tick computes its t: bit-equal offline runs
        self.frames.push(t, drive)
        try:
            if self.stepper.advance_to(t, self.frames):
                values = self._publish(self.stepper.state)
                if not all(math.isfinite(v) for v in values):
                    raise FloatingPointError("the strands produced a non-finite value")
                self.values = values
        except Exception:
            self.errors += 1
            self.restart(now, drive)
            self.values = self._publish(self.stepper.state)
        return self.values

    def capture(self) -> TailState | None:
        """The strands' state now (None before the first tick)."""
        stepper, frames = self.stepper, self.frames
        if stepper is None:
            return None
        return TailState(
            self.start,
            stepper.start,
            stepper.steps,
            stepper.state,
            stepper._last_good,
            (frames.t0, frames.t1, frames.a, frames.b),
            tuple(self.values),
            self.errors,
            self.skipped_steps,
            stepper.bad_inputs,
        )

    def restore(self, tail: TailState) -> bool:
        """Go on from ``tail`` (a dead generation's, same physics config): the next :meth:`tick`
        steps on from there, interpolating from its last tick frame to the new one. False (and
        nothing changed) when the state does not fit this model (another physics file)."""
        if len(tail.values) != len(self.names):
            return False
        stepper = FixedStepper(
            self.model.step, tail.state, self.config.rate, start=tail.stepper_start, max_catch_up=MAX_CATCH_UP
        )
        stepper.steps, stepper.bad_inputs, stepper._last_good = tail.steps, tail.bad_inputs, tail.last_good
        self.stepper, self.start = stepper, tail.start
        self.frames = TickFrames()
        self.frames.t0, self.frames.t1, self.frames.a, self.frames.b = tail.frames
        self.values = list(tail.values)
        self.errors, self._skipped_before = tail.errors, tail.skipped_steps
        return True

    @property
    def skipped_steps(self) -> int:
        """Internal steps skipped after stalls longer than :data:`MAX_CATCH_UP` steps, in total."""
        return self._skipped_before + (0 if self.stepper is None else self.stepper.skipped_steps)

    def status(self) -> dict[str, float | int]:
        stepper = self.stepper
        return {
            "channels": len(self.names),
            "rate": self.config.rate,
            "start": self.start,
            "steps": 0 if stepper is None else stepper.steps,
            "skipped_steps": self.skipped_steps,
            "errors": self.errors,
        }
