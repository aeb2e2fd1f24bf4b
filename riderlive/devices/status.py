"""What a device reports each tick: :class:`DeviceStatus`, and :class:`StopRecord` of its last e-stop.

Made by :class:`~riderlive.devices.device.Device` (``tick`` and ``status``), published by the
tick (``realtime/output.py``) to REST, the page and ``/metrics``. Times are ``perf_counter``
seconds, one clock for every process on the host.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from riderlive.devices.lifecycle import DeviceState, Fault, Transition


@dataclass
class StopRecord:
    """The last e-stop (``perf_counter`` s, one clock for every process on the host):
    requested (latch time), acted on by the bus owner, outputs-off written, read back off;
    and when the last goal write before it began (None: the plug does not say)."""

    source: str = ""
    requested_at: float | None = None
    acted_at: float | None = None
    off_written_at: float | None = None
    confirmed_at: float | None = None
    repeats: int = 0
    last_goal_at: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "source": self.source,
            "requested_at": self.requested_at,
            "acted_at": self.acted_at,
            "off_written_at": self.off_written_at,
            "confirmed_at": self.confirmed_at,
            "confirmed": self.confirmed_at is not None,
            "repeats": self.repeats,
            "last_goal_at": self.last_goal_at,
        }


@dataclass(frozen=True)
class DeviceStatus:
    """One tick of a device, for publishing (``extra``: the plug's own status)."""

    name: str
    kind: str
    state: DeviceState
    detail: str
    at: float
    fault: Fault | None
    armed_by: str | None
    outputs_off_confirmed: bool
    estop: StopRecord | None
    wrote: bool
    transitions: tuple[Transition, ...]
    counters: dict[str, int]
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the plug's fields (servos...) plus the lifecycle's."""
        return {
            **self.extra,
            "name": self.name,
            "kind": self.kind,
            "state": self.state.value,
            "detail": self.detail,
            "at": self.at,
            "fault": None if self.fault is None else self.fault.to_dict(),
            "armed_by": self.armed_by,
            "outputs_off_confirmed": self.outputs_off_confirmed,
            "estop": None if self.estop is None else self.estop.to_dict(),
            "wrote": self.wrote,
            "transitions": [t.to_dict() for t in self.transitions],
            "counters": dict(self.counters),
        }
