"""What the rig actually did on one tick, for publishing beside the rider frame."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from riderlive.dynamixel.lifecycle import Fault, RigState, Transition


@dataclass
class BusCounters:
    """Running totals since the driver was created."""

    ticks: int = 0
    goal_writes: int = 0
    reads: int = 0
    read_failures: int = 0
    fast_read_failures: int = 0
    clamps: int = 0
    bad_inputs: int = 0
    """Rider frames of the wrong length or with non-finite values (held instead)."""
    faults: int = 0
    estops: int = 0

    def to_dict(self) -> dict[str, int]:
        return dict(self.__dict__)


@dataclass(frozen=True)
class RigStatus:
    """One tick of the rig. Per-servo tuples follow the rig map's servo order.

    Degrees are servo shaft degrees; ``None`` where nothing has been read yet.
    ``tracking_error_deg`` is the goal sent minus the present position at the last read.
    """

    state: RigState
    at: float
    tick: int
    names: tuple[str, ...]
    ids: tuple[int, ...]
    goal_deg: tuple[float, ...]
    clamped: tuple[bool, ...]
    present_deg: tuple[float | None, ...]
    tracking_error_deg: tuple[float | None, ...]
    temperature_c: tuple[int | None, ...]
    voltage_v: tuple[float | None, ...]
    hardware_errors: dict[int, tuple[str, ...]]
    fault: Fault | None
    wrote: bool
    """A goal SYNC_WRITE went out on this tick."""
    read: bool
    """A (fast) sync read of present values ran on this tick."""
    fast_sync_read: bool
    transactions: int
    """Bus transactions on this tick (1 write, + 1 on read ticks; more during setup)."""
    transitions: tuple[Transition, ...] = ()
    counters: dict[str, int] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: plain lists, strings and numbers."""
        servos = [
            {
                "name": self.names[i],
                "id": self.ids[i],
                "goal_deg": self.goal_deg[i],
                "clamped": self.clamped[i],
                "present_deg": self.present_deg[i],
                "tracking_error_deg": self.tracking_error_deg[i],
                "temperature_c": self.temperature_c[i],
                "voltage_v": self.voltage_v[i],
                "hardware_error": list(self.hardware_errors.get(self.ids[i], ())),
            }
            for i in range(len(self.ids))
        ]
        return {
            "state": self.state.value,
            "at": self.at,
            "tick": self.tick,
            "servos": servos,
            "clamps": sum(self.clamped),
            "fault": None if self.fault is None else self.fault.to_dict(),
            "wrote": self.wrote,
            "read": self.read,
            "fast_sync_read": self.fast_sync_read,
            "transactions": self.transactions,
            "transitions": [t.to_dict() for t in self.transitions],
            "counters": dict(self.counters),
        }
