"""Shot scripts: a take as a TOML list of gait and move segments, and the batch path.

A script (see ``config/shots/*.toml``)::

    name = "gallop into a sliding stop"
    seed = 7            # optional: stride-to-stride variation on, reproducibly
    variation = 0.05    # optional fraction (default 0.05 with a seed, else 0 = off)

    [terrain]           # optional: the ground (default flat and level), one of
    slope = 6.0         # degrees, + uphill, or
    # profile = [[0, 0], [20, 8], [60, 8], [70, -5]]   # [distance along the ground m, slope deg]

    [[segment]]
    gait = "gallop"     # walk, trot, canter, gallop or halt
    seconds = 4         # required for a gait
    speed = 12.0        # m/s, within the gait's range (default: the gait's)
    ramp = 1.5          # optional: seconds to reach the speed, or
    # accel = 2.0       # optional: m/s^2, the speed's rate of change bound

    [[segment]]
    move = "stop"       # jump, rear, stop or buck; seconds default to the move's length

Segment ``i`` starts when segment ``i - 1`` ends; the first gait segment is the
steady state at ``t = 0``. :func:`generate` returns a whole take as a FrameTable.
"""

from __future__ import annotations

from pathlib import Path
from typing import Self

import numpy as np
import pydantic

from riderlive.channels import HORSE_NAMES
from riderlive.configfile import StrictModel, load
from riderlive.framefile import FrameTable
from riderlive.horse.gaits import GAIT_TABLE, GAITS, Gait, parse_gait
from riderlive.horse.model import Model, Perform, SetGait, State, evaluate, initial, schedule
from riderlive.horse.moves import MOVE_TABLE, MOVES, parse_move
from riderlive.horse.terrain import TerrainConfig

DEFAULT_VARIATION = 0.05
"""Stride-to-stride variation (fraction of hoof lift, trunk heave and pitch) when a seed is given."""


class Segment(StrictModel):
    """One part of a take: a gait held for ``seconds`` or a movement."""

    gait: str | None = None
    move: str | None = None
    seconds: float | None = pydantic.Field(default=None, gt=0.0, le=3600.0)
    speed: float | None = pydantic.Field(default=None, ge=0.0, le=20.0)
    ramp: float | None = pydantic.Field(default=None, gt=0.0, le=60.0)
    accel: float | None = pydantic.Field(default=None, gt=0.0, le=20.0)
    """m/s^2: the ground speed's rate of change stays within it (``model.bounded_omega``)."""

    @pydantic.model_validator(mode="after")
    def _one_kind(self) -> Self:
        if (self.gait is None) == (self.move is None):
            raise ValueError("a segment has exactly one of 'gait' or 'move'")
        if self.ramp is not None and self.accel is not None:
            raise ValueError("a segment has at most one of 'ramp' (s) or 'accel' (m/s^2)")
        if self.gait is not None:
            if self.gait not in (*GAITS, "halt"):
                raise ValueError(f"gait must be one of {', '.join((*GAITS, 'halt'))}")
            if self.seconds is None:
                raise ValueError("a gait segment needs 'seconds'")
            gait = parse_gait(self.gait)
            if gait is Gait.HALT and self.speed not in (None, 0.0):
                raise ValueError("halt has speed 0")
            if self.speed is not None and gait is not Gait.HALT:
                GAIT_TABLE[gait].check_speed(self.speed)
        else:
            if self.move not in MOVES:
                raise ValueError(f"move must be one of {', '.join(MOVES)}")
            if self.speed is not None or self.ramp is not None or self.accel is not None:
                raise ValueError("a move sets its own speed: no 'speed', 'ramp' or 'accel'")
        return self

    @property
    def duration(self) -> float:
        if self.seconds is not None:
            return self.seconds
        return MOVE_TABLE[parse_move(str(self.move))].duration

    def command(self) -> SetGait | Perform:
        if self.gait is not None:
            return SetGait(parse_gait(self.gait), self.speed, self.ramp, self.accel)
        return Perform(parse_move(str(self.move)))


class TakeHeader(StrictModel):
    """What every scripted take has besides its plan: name, variation, ground."""

    name: str = ""
    description: str = ""
    seed: int | None = pydantic.Field(default=None, ge=0, lt=2**63)
    variation: float | None = pydantic.Field(default=None, ge=0.0, le=0.3)
    terrain: TerrainConfig | None = None

    def model(self) -> Model:
        variation = (
            self.variation if self.variation is not None else (DEFAULT_VARIATION if self.seed is not None else 0.0)
        )
        terrain = self.terrain.terrain() if self.terrain is not None else None
        return Model(variation=variation, seed=self.seed or 0, terrain=terrain)


class ShotScript(TakeHeader):
    """A scripted take: segments played back to back."""

    segment: list[Segment] = pydantic.Field(min_length=1, max_length=10_000)

    @property
    def duration(self) -> float:
        return sum(s.duration for s in self.segment)

    def start(self, model: Model, t0: float = 0.0, state: State | None = None) -> State:
        """Queue the segments from ``t0`` (a fresh steady state unless ``state`` is given)."""
        segments = list(self.segment)
        if state is None:
            first = segments[0]
            if first.gait is not None:
                state = initial(model, parse_gait(first.gait), first.speed, t0)
                segments = segments[1:]
                t = t0 + first.duration
            else:
                state = initial(model, Gait.HALT, None, t0)
                t = t0
        else:
            t = t0
        for seg in segments:
            state = schedule(state, t, seg.command())
            t += seg.duration
        return state


def load_script(path: str | Path) -> ShotScript:
    """Read and validate a shot script; errors name the file and key."""
    return load(ShotScript, path)


def gait_script(gait: str, seconds: float, speed: float | None = None, seed: int | None = None) -> ShotScript:
    """A one-segment script: ``gait`` for ``seconds``; a bad name or speed is a plain ValueError."""
    parsed = parse_gait(gait)
    if speed is not None and parsed is not Gait.HALT:
        GAIT_TABLE[parsed].check_speed(speed)
    if not (0.0 < seconds <= 3600.0):
        raise ValueError(f"seconds must be within 0-3600, got {seconds!r}")
    return ShotScript(seed=seed, segment=[Segment(gait=gait, seconds=seconds, speed=speed)])


def generate(script: ShotScript, rate: float = 120.0) -> FrameTable:
    """The whole take at ``rate`` Hz as a FrameTable of every horse channel (m, deg)."""
    if not (np.isfinite(rate) and 1.0 <= rate <= 10_000.0):
        raise ValueError(f"rate must be within 1-10000 Hz, got {rate!r}")
    model = script.model()
    n = max(round(script.duration * rate), 1)
    times = np.arange(n, dtype=np.float64) / rate
    _, values = evaluate(model, script.start(model), times)
    return FrameTable(HORSE_NAMES, values, times)
