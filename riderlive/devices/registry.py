"""Which plug drives a device kind, and how a device's rate fits the tick's.

A device is configured by its kind and a file (a rig map for ``dynamixel``). The
kind's module provides two functions::

    describe(file, port) -> DeviceInfo      # validate the file; name, rate, wire budget
    make_plug(spec) -> Plug                 # the plug, in the process that drives it

:func:`plan` runs in the web process at start: it validates the file (errors name the
file and key), and fits the device to the tick: a device validated for fewer ticks per
second than the service runs is driven every ``divider``-th tick, or refused when the
policy says so, with both numbers in the message.
"""

from __future__ import annotations

import importlib
import json
import math
from dataclasses import asdict, dataclass, field
from typing import Any, Literal

from riderlive.devices.plug import Plug
from riderlive.tickframe import ALWAYS, Part, check_parts, parse_parts

KINDS: dict[str, str] = {"dynamixel": "riderlive.dynamixel.driver", "platform": "riderlive.platform.device"}
"""Device kind -> the module with ``describe`` and ``make_plug``."""
RatePolicy = Literal["divide", "refuse"]


@dataclass(frozen=True)
class DeviceInfo:
    name: str
    validated_hz: float
    """The highest tick rate the device's configuration was validated for."""
    budget: str
    """A few lines for the start-up log: the wire budget per tick."""
    consumes: frozenset[Part] = frozenset({Part.RIDER})
    """The parts of the tick's frame the device reads (the rig: the rider; a platform: the saddle)."""
    longest_wait_s: float = 0.0
    """The longest one tick may block in this device's calls (s; a reply awaited to its ceiling)."""


@dataclass(frozen=True)
class DeviceSpec:
    """A device as the tick and the guardian build it (picklable, JSON-able)."""

    kind: str
    file: str
    port: str | None
    name: str
    divider: int
    """Driven every ``divider``-th tick of the service."""
    period_s: float
    """Seconds between the device's ticks (``divider`` / tick rate)."""
    consumes: tuple[str, ...] = (Part.RIDER.value,)
    """:attr:`DeviceInfo.consumes` by name (:class:`~riderlive.tickframe.Part` values; JSON-able)."""
    options: dict[str, Any] = field(default_factory=dict)
    """Kind-specific settings for ``make_plug`` (JSON values), from the service configuration."""
    longest_wait_s: float = 0.0
    """:attr:`DeviceInfo.longest_wait_s`: the supervisor does not call a tick hung sooner."""

    def to_json(self) -> str:
        return json.dumps(asdict(self))

    @classmethod
    def from_json(cls, text: str) -> DeviceSpec:
        data: dict[str, Any] = json.loads(text)
        data["consumes"] = tuple(data.get("consumes", ()))
        return cls(**data)

    @property
    def parts(self) -> frozenset[Part]:
        """:attr:`consumes` as parts (a wrong name is a ValueError naming it)."""
        return parse_parts(self.consumes)


class RateMismatch(ValueError):
    """The device cannot follow the tick rate and the policy is to refuse."""


def _module(kind: str) -> Any:
    if kind not in KINDS:
        raise ValueError(f"unknown device kind {kind!r}; known: {', '.join(KINDS)}")
    return importlib.import_module(KINDS[kind])


def plan(
    kind: str,
    file: str,
    port: str | None,
    tick_hz: float,
    policy: RatePolicy = "divide",
    *,
    options: dict[str, Any] | None = None,
    computed: frozenset[Part] = ALWAYS,
) -> tuple[DeviceSpec, str]:
    """Validate a device and fit it to ``tick_hz``; returns the spec and what to print.

    ``computed``: the frame parts the tick computes (:func:`riderlive.tickframe.computed_parts`);
    a device consuming another is refused (:class:`~riderlive.tickframe.MissingPart`).
    """
    info: DeviceInfo = _module(kind).describe(file, port)
    check_parts(info.name, sorted(info.consumes, key=lambda p: p.value), computed)
    divider = max(1, math.ceil(tick_hz / info.validated_hz - 1e-9))
    lines = [info.budget]
    if divider > 1:
        message = f"{info.name} is validated for {info.validated_hz:g} ticks/s but the service ticks at {tick_hz:g}/s"
        if policy == "refuse":
            section = "rig" if kind == "dynamixel" else kind
            raise RateMismatch(
                f"{message}: set tick.rate <= {info.validated_hz:g} (or {section}.rate_policy = 'divide')"
            )
        lines.append(f"{message}: driving it every {divider} ticks ({tick_hz / divider:g} ticks/s)")
    consumes = tuple(sorted(p.value for p in info.consumes))
    spec = DeviceSpec(
        kind, file, port, info.name, divider, divider / tick_hz, consumes, dict(options or {}), info.longest_wait_s
    )
    return spec, "\n".join(lines)


def make_plug(spec: DeviceSpec) -> Plug:
    plug: Plug = _module(spec.kind).make_plug(spec)
    return plug
