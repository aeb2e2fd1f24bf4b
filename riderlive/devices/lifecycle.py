"""The one device lifecycle: state names, allowed transitions, typed errors and faults.

Pure bookkeeping, no I/O. :class:`Lifecycle` holds a device's :class:`DeviceState`,
refuses what the table does not allow (:class:`IllegalTransition`) and records every
change with its reason and who asked (an operator through REST, the page, the CLI; the
tick; the guardian; the device itself). The state names are those of
``coord/LIFECYCLE.md`` and are what REST, the page, ``/metrics`` and the CLI show::

    disconnected -> connecting -> disarmed --arm--> [homing ->] soft_start -> running
    running/soft_start/homing --disarm or fault--> parking -> parked (or fault)
    any --e-stop--> estop --reset--> disarmed          fault --reset--> connecting -> disarmed

Only an operator's arm leaves ``disarmed``/``parked`` toward motion; reset never arms.
"""

from __future__ import annotations

import enum
import logging
from collections import deque
from dataclasses import dataclass, field
from typing import Any

log = logging.getLogger("riderlive.devices")


class DeviceState(enum.StrEnum):
    """Where a device is; the value is the published name."""

    DISCONNECTED = "disconnected"
    CONNECTING = "connecting"
    DISARMED = "disarmed"
    HOMING = "homing"
    SOFT_START = "soft_start"
    RUNNING = "running"
    PARKING = "parking"
    PARKED = "parked"
    ESTOP = "estop"
    FAULT = "fault"

    @property
    def moving(self) -> bool:
        """Outputs on and the device following goals (homing, soft start, running, parking)."""
        return self in MOVING

    @property
    def armed(self) -> bool:
        """An operator's arm is in force (homing, soft start, running)."""
        return self in ARMED

    @property
    def latched(self) -> bool:
        return self in (DeviceState.ESTOP, DeviceState.FAULT)


ARMED = frozenset({DeviceState.HOMING, DeviceState.SOFT_START, DeviceState.RUNNING})
MOVING = ARMED | {DeviceState.PARKING}
ARMABLE = frozenset({DeviceState.DISARMED, DeviceState.PARKED})

_S = DeviceState
_ALWAYS = frozenset({_S.ESTOP, _S.DISCONNECTED})
TRANSITIONS: dict[DeviceState, frozenset[DeviceState]] = {
    _S.DISCONNECTED: frozenset({_S.CONNECTING, _S.ESTOP, _S.PARKING}),
    _S.CONNECTING: _ALWAYS | {_S.DISARMED, _S.FAULT},
    _S.DISARMED: _ALWAYS | {_S.HOMING, _S.SOFT_START, _S.CONNECTING, _S.FAULT},
    _S.HOMING: _ALWAYS | {_S.SOFT_START, _S.PARKING, _S.FAULT},
    _S.SOFT_START: _ALWAYS | {_S.RUNNING, _S.PARKING, _S.FAULT},
    _S.RUNNING: _ALWAYS | {_S.PARKING, _S.FAULT},
    _S.PARKING: _ALWAYS | {_S.PARKED, _S.FAULT},
    _S.PARKED: _ALWAYS | {_S.HOMING, _S.SOFT_START, _S.CONNECTING, _S.FAULT},
    _S.ESTOP: frozenset({_S.DISARMED, _S.CONNECTING, _S.DISCONNECTED}),
    _S.FAULT: _ALWAYS | {_S.CONNECTING},
}
"""state -> the states it may move to. E-stop is reachable from everywhere; ESTOP is
left only by reset (to disarmed, or connecting when the port must be reopened).
DISCONNECTED -> PARKING is the guardian's takeover of a device whose controller died
while it moved (a category 1 stop: the only way into motion that is not an arm)."""


# --- errors ----------------------------------------------------------------------------


class DeviceError(Exception):
    """Base of every error a device raises or records."""


class IllegalTransition(DeviceError):
    """A transition the table does not allow (a bug in the caller, never operator input)."""

    def __init__(self, source: DeviceState, target: DeviceState) -> None:
        self.source = source
        self.target = target
        super().__init__(f"cannot go from {source.value} to {target.value}")


class Refusal(enum.StrEnum):
    """Why an operator's request was refused; the value is the ``/metrics`` label."""

    UNKNOWN_DEVICE = "unknown_device"
    UNAUTHORIZED = "unauthorized"
    ESTOPPED = "estopped"
    FAULTED = "faulted"
    ALREADY_ARMED = "already_armed"
    NOT_READY = "not_ready"
    PARKING = "parking"
    NOTHING_TO_RESET = "nothing_to_reset"
    MOVING = "moving"
    TICK_DOWN = "tick_down"
    BAD_CONFIG = "bad_config"
    NO_GUARDIAN = "no_guardian"
    """No guardian (dead-man process) is alive and watching: nothing may move."""


REFUSAL_STATUS: dict[Refusal, int] = {
    Refusal.UNKNOWN_DEVICE: 404,
    Refusal.UNAUTHORIZED: 401,
    Refusal.TICK_DOWN: 503,
    Refusal.NO_GUARDIAN: 503,
    Refusal.BAD_CONFIG: 422,
}
"""HTTP status of a refusal (409 Conflict when not listed: the request is fine, the state is not)."""


class Refused(DeviceError):
    """An operator's request that the device's state does not allow; nothing changed."""

    def __init__(self, reason: Refusal, message: str) -> None:
        self.reason = reason
        super().__init__(message)


def arm_refusal(device: str, name: str, state: DeviceState, latched: bool, fault: str) -> Refused | None:
    """Why an operator's arm naming ``name`` is refused by ``device`` in ``state`` (``latched``:
    the e-stop latch is set; ``fault``: the fault's message), or None: only an arm that names
    the device, from ``disarmed`` or ``parked``, with no e-stop latched, enters motion."""
    if name != device:
        return Refused(Refusal.UNKNOWN_DEVICE, f"this is {device!r}, not {name!r}")
    if latched or state is DeviceState.ESTOP:
        return Refused(Refusal.ESTOPPED, f"{device} is e-stopped: reset first (reset never arms)")
    if state is DeviceState.FAULT:
        return Refused(Refusal.FAULTED, f"{device} has a fault ({fault}): reset first")
    if state.armed:
        return Refused(Refusal.ALREADY_ARMED, f"{device} is already armed ({state.value})")
    if state is DeviceState.PARKING:
        return Refused(Refusal.PARKING, f"{device} is parking: arm again once it is parked")
    if state not in ARMABLE:
        return Refused(Refusal.NOT_READY, f"{device} is {state.value}: wait until it is disarmed")
    return None


class StopRequested(DeviceError):
    """An e-stop is pending: the goal write was not sent (raised by the latch's gate)."""


class PortLost(DeviceError):
    """The transport cannot be opened, or vanished while in use."""


class PortBusy(DeviceError):
    """Another process holds the transport (the guardian finishing a stop, another tool)."""


class NoReply(DeviceError):
    """A unit (servo, actuator) did not answer within its budget."""

    def __init__(self, unit: int | None, detail: str, partial: dict[int, tuple[int, bytes]] | None = None) -> None:
        self.unit = unit
        self.partial = partial or {}
        """What a group read did get before it stopped: unit -> (error byte, data)."""
        super().__init__(f"unit {unit}: {detail}" if unit is not None else detail)


class HardwareFault(DeviceError):
    """A unit reports a hardware error (overload, overheating, ...): ``bits`` names them."""

    def __init__(self, unit: int, bits: tuple[str, ...], raw: int, what: str = "unit") -> None:
        self.unit = unit
        self.bits = bits
        self.raw = raw
        super().__init__(f"{what} {unit}: hardware error {', '.join(bits) or hex(raw)}")


class Mismatch(DeviceError):
    """A unit is not what the configuration says (model number, firmware)."""

    def __init__(self, unit: int, message: str) -> None:
        self.unit = unit
        super().__init__(message)


class Rejected(DeviceError):
    """A unit answered a command with an error."""

    def __init__(self, unit: int, what: str, detail: str) -> None:
        self.unit = unit
        super().__init__(f"unit {unit}: {what} rejected ({detail})")


class TickGap(DeviceError):
    """The ticks stopped longer than the device's own watchdog: it may have stopped itself."""

    def __init__(self, gap_s: float, watchdog_s: float) -> None:
        self.gap_s = gap_s
        super().__init__(
            f"no goal for {gap_s * 1000:.0f} ms (device watchdog {watchdog_s * 1000:.0f} ms): "
            "the device may have stopped itself"
        )


class SetupTimeout(DeviceError):
    """Connecting (open, check, configure) did not end within its bound: the transport stayed
    held by another process, or the units kept it busy."""


class BusErrors(DeviceError):
    """The transport's error budget is spent: failures come faster than they drain."""


# --- faults ----------------------------------------------------------------------------


class FaultKind(enum.StrEnum):
    """Why a device stopped; the value is what gets published and counted."""

    PORT_LOST = "port_lost"
    NO_REPLY = "no_reply"
    MISMATCH = "mismatch"
    HARDWARE_ERROR = "hardware_error"
    REJECTED = "rejected"
    TICK_GAP = "tick_gap"
    BUS_ERRORS = "bus_errors"
    SETUP_TIMEOUT = "setup_timeout"
    INTERNAL = "internal"


_KINDS: tuple[tuple[type[BaseException], FaultKind], ...] = (
    (PortLost, FaultKind.PORT_LOST),
    (NoReply, FaultKind.NO_REPLY),
    (Mismatch, FaultKind.MISMATCH),
    (HardwareFault, FaultKind.HARDWARE_ERROR),
    (Rejected, FaultKind.REJECTED),
    (TickGap, FaultKind.TICK_GAP),
    (BusErrors, FaultKind.BUS_ERRORS),
    (SetupTimeout, FaultKind.SETUP_TIMEOUT),
)


@dataclass(frozen=True, slots=True)
class Fault:
    """One fault: what, which unit (if one), decoded error bits, when (perf_counter s)."""

    kind: FaultKind
    message: str
    at: float
    unit: int | None = None
    bits: tuple[str, ...] = ()

    @classmethod
    def from_error(cls, error: BaseException, at: float) -> Fault:
        """Classify an exception caught by the device runner."""
        unit = getattr(error, "unit", None)
        bits = tuple(getattr(error, "bits", ()))
        for kind_of, kind in _KINDS:
            if isinstance(error, kind_of):
                return cls(kind, str(error), at, unit, bits)
        return cls(FaultKind.INTERNAL, f"{type(error).__name__}: {error}", at, unit)

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind.value,
            "message": self.message,
            "at": self.at,
            "unit": self.unit,
            "bits": list(self.bits),
        }


@dataclass(frozen=True, slots=True)
class Transition:
    """One recorded state change (``at`` in perf_counter seconds; ``by`` who asked)."""

    at: float
    source: DeviceState
    target: DeviceState
    reason: str
    by: str

    def to_dict(self) -> dict[str, Any]:
        return {"at": self.at, "from": self.source.value, "to": self.target.value, "reason": self.reason, "by": self.by}


@dataclass
class Lifecycle:
    """A device's current state, the table's guard, and a record of changes."""

    name: str = "device"
    state: DeviceState = DeviceState.DISCONNECTED
    history: deque[Transition] = field(default_factory=lambda: deque(maxlen=256))
    transitions: int = 0
    _unpublished: deque[Transition] = field(default_factory=lambda: deque(maxlen=256))

    def can(self, target: DeviceState) -> bool:
        return target is self.state or target in TRANSITIONS[self.state]

    def go(self, target: DeviceState, at: float, reason: str, by: str) -> Transition | None:
        """Move to ``target`` (no-op when already there) or raise IllegalTransition."""
        if target is self.state:
            return None
        if target not in TRANSITIONS[self.state]:
            raise IllegalTransition(self.state, target)
        record = Transition(at, self.state, target, reason, by)
        self.state = target
        self.transitions += 1
        self.history.append(record)
        self._unpublished.append(record)
        level = logging.WARNING if target in (DeviceState.FAULT, DeviceState.ESTOP) else logging.INFO
        log.log(level, "%s: %s -> %s: %s (by %s)", self.name, record.source.value, target.value, reason, by)
        return record

    def drain(self) -> tuple[Transition, ...]:
        """The transitions since the last call (published beside the status)."""
        out = tuple(self._unpublished)
        self._unpublished.clear()
        return out
