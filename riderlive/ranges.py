"""Plausible ranges of channels: what the service accepts at its edge and what it publishes.

A range is ``(low, high)`` in **metres** for lengths, **degrees** for rotations and
plain numbers for unitless attributes, whatever the service's own length unit is
(:meth:`Ranges.limits` converts). Lookup order for a channel name:

1. the deployment's overrides (``[ranges.channels]`` in the service config), then
   :data:`CHANNEL_DEFAULTS`: an exact name or an ``fnmatch`` pattern (``"*Hoof.t*"``),
   the first match wins;
2. the default of the channel's kind (:data:`KIND_DEFAULTS`), decided by its
   attribute (``tx ty tz``: length, ``rx ry rz``: rotation, anything else: unitless).

So a channel added later (``neck.rx``) has a range on day one. The
defaults are generous (a jumping horse's hooves rise about 1.5 m, a rearing horse
pitches about 70 degrees); they exist to stop values no horse or rider makes (1e300,
a length unit mistake of 10^6) before they reach the rules, the filters or a servo.
"""

from __future__ import annotations

import fnmatch
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from functools import lru_cache

from riderlive.channels import Kind
from riderlive.units import metres_per_unit

Range = tuple[float, float]

KIND_DEFAULTS: dict[Kind, Range] = {
    Kind.TRANSLATION: (-10.0, 10.0),
    Kind.ROTATION: (-360.0, 360.0),
    Kind.ATTRIBUTE: (-1e4, 1e4),
}
"""Per kind, for every channel no pattern names (metres, degrees, unitless)."""

CHANNEL_DEFAULTS: dict[str, Range] = {
    "*Hoof.t*": (-5.0, 5.0),
    "rearPivot.t*": (-2.0, 2.0),
    "rearPivot.r*": (-90.0, 90.0),
    "backMid.rz": (-90.0, 90.0),
    "saddle.t*": (-1.5, 1.5),
    "saddle.r*": (-90.0, 90.0),
    "root.t*": (-1e5, 1e5),
    "root.ry": (-1e6, 1e6),
    "ground.rz": (-45.0, 45.0),
    "ground.ty": (-1e5, 1e5),
    "tail_*.t*": (-1e5, 1e5),
    "braid_*.t*": (-1e5, 1e5),
    "*_cloth_*.t*": (-1e5, 1e5),
    "tail_ref.t*": (-1e5, 1e5),
}
"""The horse's hooves and pivots are relative to its body; ``root`` is its world
position (100 km) and heading (turns accumulate), ``ground`` the slope under it (a
horse climbs no steeper than 45 degrees) and its height; the simulated tail, braid and cloth flaps are
world positions too."""


def kind_of_name(name: str) -> Kind:
    """The kind of a ``node.attr`` channel from its attribute alone."""
    attr = name.rpartition(".")[2]
    if attr in ("tx", "ty", "tz"):
        return Kind.TRANSLATION
    if attr in ("rx", "ry", "rz"):
        return Kind.ROTATION
    return Kind.ATTRIBUTE


def check_range(where: str, value: Range) -> Range:
    """``value`` as a valid range (finite, low < high), or ValueError naming ``where``."""
    low, high = float(value[0]), float(value[1])
    if not (abs(low) < float("inf") and abs(high) < float("inf") and low < high):
        raise ValueError(f"{where}: a range is [low, high] with finite low < high, got {list(value)}")
    return low, high


@dataclass(frozen=True)
class Ranges:
    """The ranges in force; ``overrides`` (name or pattern -> range) win over the defaults."""

    overrides: Mapping[str, Range] = field(default_factory=dict)
    kinds: Mapping[Kind, Range] = field(default_factory=lambda: dict(KIND_DEFAULTS))

    def __post_init__(self) -> None:
        for key, value in self.overrides.items():
            check_range(key, value)
        for kind, value in self.kinds.items():
            check_range(kind.value, value)
        object.__setattr__(self, "_hash", hash((tuple(self.overrides.items()), tuple(self.kinds.items()))))

    def of(self, name: str) -> Range:
        """The range of channel ``name`` in metres, degrees or plain numbers."""
        return _lookup(self, name)

    def limits(self, names: Iterable[str], length_scale: float) -> tuple[list[float], list[float]]:
        """Lows and highs of ``names`` in the service's units (a length unit is L/25 m)."""
        m = metres_per_unit(length_scale)
        lows, highs = [], []
        for name in names:
            low, high = self.of(name)
            if kind_of_name(name) is Kind.TRANSLATION:
                low, high = low / m, high / m
            lows.append(low)
            highs.append(high)
        return lows, highs

    def __hash__(self) -> int:
        return self._hash  # type: ignore[attr-defined,no-any-return]


@lru_cache(maxsize=8192)
def _lookup(ranges: Ranges, name: str) -> Range:
    for table in (ranges.overrides, CHANNEL_DEFAULTS):
        if name in table:
            return table[name]
        for pattern, value in table.items():
            if fnmatch.fnmatchcase(name, pattern):
                return value
    return ranges.kinds.get(kind_of_name(name), KIND_DEFAULTS[kind_of_name(name)])


DEFAULT_RANGES = Ranges()
