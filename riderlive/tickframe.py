"""The tick's frame: what one tick computed, typed, in metres and degrees, handed to every consumer.

The tick (:class:`riderlive.realtime.core.TickCore`) works in the service's length unit;
its consumers (the devices, the tail physics, the poses) want metres. :class:`TickFrame`
is built once per tick from the tick's result (:meth:`TickFrame.build` with the factor of
``realtime/edges.UnitEdges``, the only place lengths are converted on that path) and is
frozen: a consumer cannot change what the next one sees.

Frames and units (``riderlive.channels``): right-handed, +X forward, +Y up, +Z right;
lengths in **metres**, rotations in **degrees**, attributes unitless.

- ``rider``: ``channels.RIDER`` order; ``horse``: ``channels.HORSE`` order;
- ``saddle``: ``channels.SADDLE`` of ``horse`` at the service's configured saddle point
  (``[saddle] forward, up``), the pose a motion platform follows;
- ``estimate``: the saddle estimator's view while a saddle stream drives, else None;
- ``t`` engine seconds of the tick, ``at`` its deadline (``perf_counter`` s, the device
  clock), ``source_time`` the producer's time shown, ``tick`` its index; ``flags``.

A device says which parts it consumes (:class:`Part`, ``DeviceInfo.consumes``);
:func:`check_parts` refuses, at configuration, a device that wants a part the tick
never computes (the saddle estimate when no saddle stream can drive), naming both.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

from riderlive.units import Lengths, horse_lengths, rider_lengths, saddle_lengths


class Part(enum.Enum):
    """A part of the tick's frame a consumer may ask for."""

    RIDER = "rider"
    HORSE = "horse"
    SADDLE = "saddle"
    """The saddle pose at the configured point (always computed)."""
    ESTIMATE = "estimate"
    """The saddle estimate: only while a saddle stream (``/ws/saddle``) drives."""


ALWAYS: frozenset[Part] = frozenset({Part.RIDER, Part.HORSE, Part.SADDLE})
"""The parts every tick computes."""


class Flag(enum.IntFlag):
    """What kind of tick made the frame."""

    INPUT = 1
    """A producer's stream drove (horse or saddle)."""
    PROCEDURAL = 2
    """The procedural horse drove."""
    NEUTRAL = 4
    """Nothing drove: the neutral pose (easing to it, or held there)."""
    SADDLE_INPUT = 8
    """The driving stream is a saddle stream (``estimate`` is set)."""
    HELD = 16
    """The tick's step failed or was not finite: this is the last good frame again."""


class Estimate(NamedTuple):
    """The saddle estimate of a tick (``realtime.record.ESTIMATE_FIELDS``)."""

    lock: int
    """Lock code (``realtime.saddle_input.LOCKS``: no_signal 0, still 1, searching 2, locked 3)."""
    gait: int
    """Gait code (``realtime.saddle_input.GAITS``), -1 for none yet."""
    stride_hz: float
    phase: float
    """Stride phase, 0-1."""
    age: float
    """Seconds since the last saddle sample (NaN before one)."""

    @classmethod
    def from_row(cls, row: Sequence[float]) -> Estimate | None:
        """From a record's estimate fields; None when the lock code is NaN (no saddle drives)."""
        if len(row) != 5 or math.isnan(row[0]):
            return None
        gait = -1 if math.isnan(row[1]) else int(row[1])
        return cls(int(row[0]), gait, float(row[2]), float(row[3]), float(row[4]))


@dataclass(frozen=True, slots=True)
class TickFrame:
    """One tick's frame (see the module docstring for frames and units)."""

    tick: int
    t: float
    """Engine seconds of this tick."""
    at: float
    """The tick's deadline, ``perf_counter`` seconds (the devices' clock)."""
    source_time: float
    """The producer's time of the horse shown (engine time when no producer drives)."""
    flags: Flag
    rider: tuple[float, ...]
    horse: tuple[float, ...]
    saddle: tuple[float, ...]
    estimate: Estimate | None = None

    @classmethod
    def build(  # noqa: PLR0917
        cls,
        tick: int,
        t: float,
        at: float,
        source_time: float,
        flags: Flag,
        rider: Sequence[float],
        horse: Sequence[float] = (),
        saddle: Sequence[float] = (),
        estimate: Sequence[float] = (),
        metres_per_unit: float = 1.0,
    ) -> TickFrame:
        """The frame of values in the service's unit (``metres_per_unit`` m each): lengths to metres.

        A part left empty is one the caller does not compute (a rider-only drive): a
        consumer of it counts a bad input and holds.
        """
        return cls(
            tick,
            t,
            at,
            source_time,
            flags,
            _metres(rider_lengths(metres_per_unit), rider),
            _metres(horse_lengths(metres_per_unit), horse),
            _metres(saddle_lengths(metres_per_unit), saddle),
            Estimate.from_row(estimate),
        )

    def wanting(self, parts: frozenset[Part]) -> tuple[Part, ...]:
        """The parts of ``parts`` this frame lacks (the estimate while no saddle drives)."""
        return (Part.ESTIMATE,) if Part.ESTIMATE in parts and self.estimate is None else ()


def _metres(lengths: Lengths, values: Sequence[float]) -> tuple[float, ...]:
    return tuple(lengths.to_metres(values)) if values else ()


class MissingPart(ValueError):
    """A device asks for a frame part the tick does not compute (names device and part)."""

    def __init__(self, device: str, part: Part, why: str) -> None:
        self.device, self.part = device, part
        super().__init__(f"device {device!r} consumes the tick frame's {part.value!r}, which {why}")


def computed_parts(saddle_input: bool) -> frozenset[Part]:
    """The parts the tick computes: the estimate only when a saddle stream can drive it."""
    return ALWAYS | {Part.ESTIMATE} if saddle_input else ALWAYS


def check_parts(device: str, consumes: Iterable[Part], computed: frozenset[Part]) -> None:
    """Raise :class:`MissingPart` for the first part of ``consumes`` that ``computed`` lacks."""
    for part in consumes:
        if part not in computed:
            why = (
                "exists only while a saddle stream drives, and this configuration has none"
                if part is Part.ESTIMATE
                else "this tick does not compute"
            )
            raise MissingPart(device, part, why)


def parse_parts(names: Iterable[str]) -> frozenset[Part]:
    """Parts by their names (``DeviceSpec.consumes``, JSON); a wrong name is a ValueError naming it."""
    out = set()
    for name in names:
        try:
            out.add(Part(name))
        except ValueError:
            known = ", ".join(p.value for p in Part)
            raise ValueError(f"unknown tick frame part {name!r} (known: {known})") from None
    return frozenset(out)
