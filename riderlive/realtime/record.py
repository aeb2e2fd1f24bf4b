"""The output record (tick -> web, one row per tick): one layout, packed by the tick, read by name.

:class:`RecordLayout` is made once from the tick's setup (the physics channels it runs;
the rider parts) and travels in :class:`~riderlive.realtime.setup.TickSetup` to the tick
process: the tick packs each record with :meth:`RecordLayout.pack`, and every reader (the
hub and its codecs, the pose cache, VMC, Foxglove, timecodes, the recorder, the NATS rig
node, a spare's hand-over) reads a :class:`Field` by name, never a hand-written offset.
A tick whose own layout differs from the setup's refuses to start (:class:`LayoutMismatch`
names both). A new channel family is one more :class:`Field` here.

Every slot is a little-endian float64 (``dtype`` says how a field's values are read:
``int64`` values are exact in float64). Times are engine seconds (``perf_counter`` minus
the service's start). Lengths are service length units (``tick.length_scale``), angles
degrees. The fields, in order (the head's offsets are the same in every layout)::

    seq        tick number (0, 1, 2...; a gap means skipped deadlines)
    engine_t   the tick's deadline
    source_t   source time shown (producer time for input, engine time otherwise)
    driver     Driver code: 0 procedural, 1 input, 2 neutral
    producer   producer id for input, -1 otherwise
    input_rx   engine receive time of the newest input frame taken this tick, or -1
    done       engine time the tick finished computing
    lateness   seconds the tick woke after its deadline
    saddle     the saddle pose of this tick's horse (channels.SADDLE)
    estimate   the saddle estimate (ESTIMATE_FIELDS; all NaN unless a saddle input drives)
    horse      horse channels (channels.HORSE order)
    rider      rider channels (channels.RIDER order)
    physics    the tail and braid channels when the tick runs them (else empty)
    parts      the rider parts (channels.RIDER_PARTS)

The published channels (``/ws/rider``) are ``rider`` and everything after it: :attr:`RecordLayout.published`.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from riderlive.channels import HORSE_NAMES, RIDER_NAMES, SADDLE_NAMES
from riderlive.channels import RIDER_PART_NAMES as PART_NAMES

FloatArray = npt.NDArray[np.float64]

ESTIMATE_FIELDS: tuple[str, ...] = ("lock", "gait", "stride_hz", "phase", "age")
"""The saddle estimate in a record: lock and gait as codes (``riderlive.realtime.saddle_input``),
stride frequency (Hz), phase (0-1), age (s since the last sample)."""


class LayoutMismatch(ValueError):
    """A process built from another record layout than its peer's: refused, never misread."""


@dataclasses.dataclass(frozen=True)
class Field:
    """One named run of slots ``[start, stop)`` of a record."""

    name: str
    start: int
    stop: int
    unit: str
    dtype: str = "float64"
    """How the values are read (every slot is stored as float64; ``int64`` values are exact)."""
    channels: tuple[str, ...] = ()
    """The channel names of a field of several slots, in order (empty for a single value)."""

    @property
    def slice(self) -> slice:
        return slice(self.start, self.stop)

    @functools.cached_property
    def width(self) -> int:
        return self.stop - self.start

    def of(self, row: FloatArray) -> FloatArray:
        """The field's slots of ``row`` (a view, no copy)."""
        return row[self.start : self.stop]

    def at(self, row: FloatArray) -> float:
        """A single-slot field's value in ``row``."""
        return float(row[self.start])

    def count(self, row: FloatArray) -> int:
        """A single-slot ``int64`` field's value in ``row``."""
        return int(row[self.start])

    def describe(self) -> str:
        return f"{self.name}[{self.start}]" if self.width == 1 else f"{self.name}[{self.start}:{self.stop}]"


def _run(start: int, name: str, unit: str, channels: Sequence[str]) -> Field:
    return Field(name, start, start + len(channels), unit, "float64", tuple(channels))


_SCALARS = (
    ("seq", "tick", "int64"),
    ("engine_t", "s", "float64"),
    ("source_t", "s", "float64"),
    ("driver", "Driver code", "int64"),
    ("producer", "producer id", "int64"),
    ("input_rx", "s", "float64"),
    ("done", "s", "float64"),
    ("lateness", "s", "float64"),
)
_HEAD_SCALARS = tuple(Field(name, i, i + 1, unit, dtype) for i, (name, unit, dtype) in enumerate(_SCALARS))
_SADDLE = _run(len(_SCALARS), "saddle", "service length units, deg", SADDLE_NAMES)
_ESTIMATE = _run(_SADDLE.stop, "estimate", "codes, Hz, cycles, s", ESTIMATE_FIELDS)
_HORSE = _run(_ESTIMATE.stop, "horse", "service length units, deg", HORSE_NAMES)
_RIDER = _run(_HORSE.stop, "rider", "service length units, deg", RIDER_NAMES)
HEAD: tuple[Field, ...] = (*_HEAD_SCALARS, _SADDLE, _ESTIMATE, _HORSE, _RIDER)
"""The fields every layout starts with, at the same offsets."""


@dataclasses.dataclass(frozen=True)
class RecordValues:
    """One record's values by field (what :meth:`RecordLayout.unpack` gives, :meth:`RecordLayout.pack` takes)."""

    seq: int
    engine_t: float
    source_t: float
    driver: int
    producer: int
    input_rx: float
    done: float
    lateness: float
    saddle: tuple[float, ...]
    estimate: tuple[float, ...]
    horse: tuple[float, ...]
    rider: tuple[float, ...]
    physics: tuple[float, ...]
    parts: tuple[float, ...]


@dataclasses.dataclass(frozen=True)
class RecordLayout:
    """The output record's fields for one tick setup (picklable: it travels in the setup).

    The head's fields are class attributes (``RecordLayout.seq``, ``RecordLayout.rider``):
    a reader with no layout at hand reads them all the same; the tail's (``physics``,
    ``parts``, ``published``) depend on the setup.
    """

    physics_channels: tuple[str, ...] = ()
    """The tail and braid channels (``realtime.tail.physics_channels``) when the tick runs them."""
    part_channels: tuple[str, ...] = PART_NAMES

    seq: ClassVar[Field] = _HEAD_SCALARS[0]
    engine_t: ClassVar[Field] = _HEAD_SCALARS[1]
    source_t: ClassVar[Field] = _HEAD_SCALARS[2]
    driver: ClassVar[Field] = _HEAD_SCALARS[3]
    producer: ClassVar[Field] = _HEAD_SCALARS[4]
    input_rx: ClassVar[Field] = _HEAD_SCALARS[5]
    done: ClassVar[Field] = _HEAD_SCALARS[6]
    lateness: ClassVar[Field] = _HEAD_SCALARS[7]
    saddle: ClassVar[Field] = _SADDLE
    estimate: ClassVar[Field] = _ESTIMATE
    horse: ClassVar[Field] = _HORSE
    rider: ClassVar[Field] = _RIDER

    @functools.cached_property
    def physics(self) -> Field:
        return _run(_RIDER.stop, "physics", "service length units, deg", self.physics_channels)

    @functools.cached_property
    def parts(self) -> Field:
        return _run(self.physics.stop, "parts", "service length units, deg", self.part_channels)

    @functools.cached_property
    def fields(self) -> tuple[Field, ...]:
        """Every field, in record order."""
        return (*HEAD, self.physics, self.parts)

    @functools.cached_property
    def width(self) -> int:
        """Slots per record."""
        return self.parts.stop

    @property
    def extra_channels(self) -> tuple[str, ...]:
        """The channels after the rider's: the physics', then the parts'."""
        return (*self.physics_channels, *self.part_channels)

    @functools.cached_property
    def published(self) -> Field:
        """The channels ``/ws/rider`` publishes: the rider's and every one after it."""
        return Field("published", _RIDER.start, self.width, "service length units, deg", "float64", self.names)

    @functools.cached_property
    def names(self) -> tuple[str, ...]:
        """The published channels' names (rider, physics, parts)."""
        return (*RIDER_NAMES, *self.extra_channels)

    def field(self, name: str) -> Field:
        for f in self.fields:
            if f.name == name:
                return f
        raise KeyError(f"no record field {name!r} (fields: {', '.join(f.name for f in self.fields)})")

    def span(self, first: str, last: str) -> slice:
        """The slots from field ``first`` through field ``last`` (adjacent fields read as one run)."""
        return slice(self.field(first).start, self.field(last).stop)

    def describe(self) -> str:
        """The layout in one line (for errors naming two layouts)."""
        return f"{self.width} slots: " + " ".join(f.describe() for f in self.fields if f.width)

    def require_same(self, other: RecordLayout, mine: str, theirs: str) -> None:
        """Refuse a peer built from another layout, naming both (``mine``, ``theirs``: who built each)."""
        if other != self:
            raise LayoutMismatch(
                f"the output record's layout differs: {mine} has {self.describe()} "
                f"(extra channels {list(self.extra_channels)}), {theirs} has {other.describe()} "
                f"(extra channels {list(other.extra_channels)})"
            )

    def pack(
        self,
        *,
        seq: int,
        engine_t: float,
        source_t: float,
        driver: int,
        producer: int,
        input_rx: float,
        done: float,
        lateness: float,
        saddle: Sequence[float],
        estimate: Sequence[float],
        horse: Sequence[float],
        rider: Sequence[float],
        physics: Sequence[float],
        parts: Sequence[float],
    ) -> list[float]:
        """One record's slots in layout order; a field of the wrong length is a ValueError naming it."""
        widths = (len(saddle), len(estimate), len(horse), len(rider), len(physics), len(parts))
        if widths != self._run_widths:
            runs = (_SADDLE, _ESTIMATE, _HORSE, _RIDER, self.physics, self.parts)
            f, got = next((f, n) for f, n in zip(runs, widths, strict=True) if n != f.width)
            raise ValueError(f"record field {f.name!r} needs {f.width} values, got {got}")
        head = [float(seq), engine_t, source_t, float(driver), float(producer), input_rx, done, lateness]
        return [*head, *saddle, *estimate, *horse, *rider, *physics, *parts]

    @functools.cached_property
    def _run_widths(self) -> tuple[int, ...]:
        return tuple(f.width for f in (_SADDLE, _ESTIMATE, _HORSE, _RIDER, self.physics, self.parts))

    def pack_values(self, values: RecordValues) -> list[float]:
        return self.pack(**{f.name: getattr(values, f.name) for f in dataclasses.fields(values)})

    def unpack(self, row: FloatArray) -> RecordValues:
        """A record's values by field (a copy; for tests and tools, not the hot path)."""
        if len(row) != self.width:
            raise LayoutMismatch(f"a record of {len(row)} slots read with a layout of {self.describe()}")
        runs = {f.name: tuple(float(x) for x in f.of(row)) for f in (*HEAD[8:], self.physics, self.parts)}
        scalars: dict[str, float | int] = {
            f.name: (f.count(row) if f.dtype == "int64" else f.at(row)) for f in _HEAD_SCALARS
        }
        return RecordValues(**scalars, **runs)  # type: ignore[arg-type]
