"""Length units: the one place where the service's length unit meets metres.

The service speaks lengths in a unit of its choice: ``tick.length_scale`` is thesis rig
units per service unit, and the thesis rig has :data:`RIG_UNITS_PER_METRE` units per
metre, so one service unit is ``length_scale / 25`` metres (:func:`metres_per_unit`;
``length_scale = 25``, the default, is metres). Rotations are degrees and attributes
unitless everywhere, so only lengths (``Kind.TRANSLATION`` channels) convert.

The conversion happens at the edges only: frames entering the tick's consumers (devices,
physics, poses) are turned into metres once (:class:`Lengths`), files and wires keep
their recorded unit. In the tick, every such crossing goes through one adapter,
``realtime/edges.UnitEdges`` (the core itself computes in the service unit). A leaf: it
imports nothing of the project but ``channels``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TypeVar

import numpy as np
import numpy.typing as npt

from riderlive.channels import HORSE, RIDER, SADDLE, Channel, Kind

RIG_UNITS_PER_METRE = 25.0
"""Thesis rig units per metre (a 1.6 m horse is 40 units tall at the withers)."""

FloatArray = npt.NDArray[np.float64]
A = TypeVar("A", bound=FloatArray)


def metres_per_unit(length_scale: float) -> float:
    """Metres per service length unit for a service of ``length_scale`` rig units per unit."""
    if not (math.isfinite(length_scale) and length_scale > 0.0):
        raise ValueError(f"length_scale must be a finite number > 0, got {length_scale!r}")
    return length_scale / RIG_UNITS_PER_METRE


def units_per_metre(length_scale: float) -> float:
    """Service length units per metre (the inverse of :func:`metres_per_unit`, computed as
    ``RIG_UNITS_PER_METRE / length_scale`` so a scale of 25 gives exactly 1)."""
    metres_per_unit(length_scale)  # the same check
    return RIG_UNITS_PER_METRE / length_scale


def length_columns(channels: Sequence[Channel]) -> tuple[int, ...]:
    """Indices of the length (translation) channels of ``channels``."""
    return tuple(i for i, c in enumerate(channels) if c.kind is Kind.TRANSLATION)


HORSE_LENGTHS = length_columns(HORSE)
RIDER_LENGTHS = length_columns(RIDER)
SADDLE_LENGTHS = length_columns(SADDLE)


@dataclass(frozen=True, slots=True)
class Lengths:
    """Converts one frame layout's lengths by a fixed factor (``factor`` metres per unit).

    ``to_metres`` / ``from_metres`` return new lists (floats) or arrays; a factor of 1
    returns the values unchanged (as a list for sequences).
    """

    columns: tuple[int, ...]
    factor: float

    def to_metres(self, values: Sequence[float]) -> list[float]:
        out = list(values)
        if self.factor != 1.0:
            k = self.factor
            for i in self.columns:
                out[i] *= k
        return out

    def from_metres(self, values: Sequence[float]) -> list[float]:
        out = list(values)
        if self.factor != 1.0:
            k = self.factor
            for i in self.columns:
                out[i] /= k
        return out

    def rows_to_metres(self, rows: A) -> A:
        """``(N, C)`` rows scaled in place (lengths only); returns ``rows``."""
        if self.factor != 1.0 and self.columns:
            rows[:, list(self.columns)] *= self.factor
        return rows


def horse_lengths(factor: float) -> Lengths:
    return Lengths(HORSE_LENGTHS, factor)


def rider_lengths(factor: float) -> Lengths:
    return Lengths(RIDER_LENGTHS, factor)


def saddle_lengths(factor: float) -> Lengths:
    return Lengths(SADDLE_LENGTHS, factor)
