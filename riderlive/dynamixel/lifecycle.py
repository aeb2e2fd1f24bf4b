"""The rig's safety lifecycle: states, allowed transitions, faults and typed errors.

Pure bookkeeping, no I/O: :class:`Lifecycle` holds the current :class:`RigState`,
refuses transitions the table does not allow (:class:`IllegalTransition`), logs
every transition and keeps them for publishing. The driver decides *when* to move;
this module decides *whether* it may.

Normal path::

    CLOSED -> CONNECTING -> CHECKING -> CONFIGURING -> SOFT_START -> RUNNING
           -> PARKING -> TORQUE_OFF -> CLOSED

E-stop goes to ESTOP from any state; a fault goes to FAULT (through PARKING when the
bus still works). Both are latched: only ``reset()`` / ``reconnect()`` leave them.
"""

from __future__ import annotations

import enum
import logging
from collections import deque
from dataclasses import dataclass, field
from typing import Any

log = logging.getLogger("riderlive.dynamixel")


class RigState(enum.Enum):
    """Where the rig is in its lifecycle; the value is what gets published."""

    CLOSED = "closed"  # port closed, nothing powered by us
    CONNECTING = "connecting"  # opening the serial port
    CHECKING = "checking"  # ping every id, model numbers, Hardware Error Status
    CONFIGURING = "configuring"  # return delay, mode, limits, profiles, torque on, watchdog
    SOFT_START = "soft_start"  # ramp from the present positions to the rider's pose
    RUNNING = "running"  # one goal write per tick, following the rider
    PARKING = "parking"  # ramp to the park pose, then torque off
    TORQUE_OFF = "torque_off"  # parked, torque off, port open; reset() starts again
    ESTOP = "estop"  # torque off by e-stop; latched until reset()
    FAULT = "fault"  # torque off after a fault; latched until reset()/reconnect()

    @property
    def torque_may_be_on(self) -> bool:
        """True in the states where the driver keeps torque on."""
        return self in _TORQUE_ON


_TORQUE_ON = frozenset({RigState.SOFT_START, RigState.RUNNING, RigState.PARKING})

_S = RigState
TRANSITIONS: dict[RigState, frozenset[RigState]] = {
    _S.CLOSED: frozenset({_S.CONNECTING, _S.ESTOP}),
    _S.CONNECTING: frozenset({_S.CHECKING, _S.FAULT, _S.ESTOP, _S.CLOSED}),
    _S.CHECKING: frozenset({_S.CONFIGURING, _S.TORQUE_OFF, _S.FAULT, _S.ESTOP, _S.CLOSED}),
    _S.CONFIGURING: frozenset({_S.SOFT_START, _S.TORQUE_OFF, _S.FAULT, _S.ESTOP, _S.CLOSED}),
    _S.SOFT_START: frozenset({_S.RUNNING, _S.PARKING, _S.FAULT, _S.ESTOP, _S.CLOSED}),
    _S.RUNNING: frozenset({_S.PARKING, _S.FAULT, _S.ESTOP, _S.CLOSED}),
    _S.PARKING: frozenset({_S.TORQUE_OFF, _S.FAULT, _S.ESTOP, _S.CLOSED}),
    _S.TORQUE_OFF: frozenset({_S.CHECKING, _S.FAULT, _S.ESTOP, _S.CLOSED}),
    _S.ESTOP: frozenset({_S.CONNECTING, _S.CHECKING, _S.FAULT, _S.CLOSED}),
    _S.FAULT: frozenset({_S.CONNECTING, _S.CHECKING, _S.ESTOP, _S.CLOSED}),
}
"""state -> the states it may move to. CLOSED is always reachable (close())."""


class RigError(Exception):
    """Base of every error the rig driver raises or records."""


class IllegalTransition(RigError):
    """A transition the lifecycle table does not allow."""

    def __init__(self, source: RigState, target: RigState) -> None:
        self.source = source
        self.target = target
        super().__init__(f"the rig cannot go from {source.value} to {target.value}")


class PortLost(RigError):
    """The serial port cannot be opened, or vanished while in use."""


class ServoSilent(RigError):
    """A servo did not answer (within the retry budget)."""

    def __init__(self, servo_id: int | None, detail: str, partial: dict[int, tuple[int, bytes]] | None = None) -> None:
        self.servo_id = servo_id
        self.partial = partial or {}
        """What a group read did get before it stopped: id -> (ERR byte, data)."""
        super().__init__(f"servo {servo_id}: {detail}" if servo_id is not None else detail)


class ModelMismatch(RigError):
    """A servo answered a ping with a model number other than the rig map's."""

    def __init__(self, servo_id: int, expected: int, found: int) -> None:
        self.servo_id = servo_id
        self.expected = expected
        self.found = found
        super().__init__(f"servo {servo_id}: model number {found}, the rig map expects {expected}")


class ServoHardwareError(RigError):
    """A servo reports Hardware Error Status bits (it has shut its torque off)."""

    def __init__(self, servo_id: int, bits: tuple[str, ...], raw: int) -> None:
        self.servo_id = servo_id
        self.bits = bits
        self.raw = raw
        super().__init__(f"servo {servo_id}: hardware error {', '.join(bits) or hex(raw)}")


class ServoRejected(RigError):
    """A servo answered an instruction with an error in its status packet."""

    def __init__(self, servo_id: int, what: str, detail: str) -> None:
        self.servo_id = servo_id
        super().__init__(f"servo {servo_id}: {what} rejected ({detail})")


class TickGap(RigError):
    """The ticks stopped for longer than the Bus Watchdog: the servos stopped themselves."""

    def __init__(self, gap_s: float, watchdog_s: float) -> None:
        self.gap_s = gap_s
        super().__init__(
            f"no goal write for {gap_s * 1000:.0f} ms (Bus Watchdog {watchdog_s * 1000:.0f} ms): "
            "the servos may have stopped themselves"
        )


class FaultKind(enum.Enum):
    """Why the rig stopped; the value is what gets published."""

    PORT_LOST = "port_lost"
    NO_REPLY = "no_reply"
    MODEL_MISMATCH = "model_mismatch"
    HARDWARE_ERROR = "hardware_error"
    REJECTED = "rejected"
    TICK_GAP = "tick_gap"
    INTERNAL = "internal"


@dataclass(frozen=True, slots=True)
class Fault:
    """One fault: what, which servo (if one), the decoded error bits, when (perf_counter s)."""

    kind: FaultKind
    message: str
    at: float
    servo_id: int | None = None
    bits: tuple[str, ...] = ()

    @classmethod
    def from_error(cls, error: BaseException, at: float) -> Fault:
        """Classify an exception caught by the driver."""
        servo_id = getattr(error, "servo_id", None)
        if isinstance(error, PortLost):
            return cls(FaultKind.PORT_LOST, str(error), at)
        if isinstance(error, ServoSilent):
            return cls(FaultKind.NO_REPLY, str(error), at, servo_id)
        if isinstance(error, ModelMismatch):
            return cls(FaultKind.MODEL_MISMATCH, str(error), at, servo_id)
        if isinstance(error, ServoHardwareError):
            return cls(FaultKind.HARDWARE_ERROR, str(error), at, servo_id, error.bits)
        if isinstance(error, ServoRejected):
            return cls(FaultKind.REJECTED, str(error), at, servo_id)
        if isinstance(error, TickGap):
            return cls(FaultKind.TICK_GAP, str(error), at)
        return cls(FaultKind.INTERNAL, f"{type(error).__name__}: {error}", at, servo_id)

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind.value,
            "message": self.message,
            "at": self.at,
            "servo_id": self.servo_id,
            "bits": list(self.bits),
        }


@dataclass(frozen=True, slots=True)
class Transition:
    """One recorded state change (``at`` in perf_counter seconds)."""

    at: float
    source: RigState
    target: RigState
    reason: str

    def to_dict(self) -> dict[str, Any]:
        return {"at": self.at, "from": self.source.value, "to": self.target.value, "reason": self.reason}


@dataclass
class Lifecycle:
    """The current state, the transition table's guard, and a record of changes."""

    state: RigState = RigState.CLOSED
    history: deque[Transition] = field(default_factory=lambda: deque(maxlen=256))
    _unpublished: list[Transition] = field(default_factory=list)

    def can(self, target: RigState) -> bool:
        return target is self.state or target in TRANSITIONS[self.state]

    def go(self, target: RigState, at: float, reason: str) -> Transition | None:
        """Move to ``target`` (a no-op when already there) or raise IllegalTransition."""
        if target is self.state:
            return None
        if target not in TRANSITIONS[self.state]:
            raise IllegalTransition(self.state, target)
        record = Transition(at, self.state, target, reason)
        self.state = target
        self.history.append(record)
        self._unpublished.append(record)
        if len(self._unpublished) > 256:
            del self._unpublished[:-256]
        level = logging.WARNING if target in (RigState.FAULT, RigState.ESTOP) else logging.INFO
        log.log(level, "rig %s -> %s: %s", record.source.value, target.value, reason)
        return record

    def drain(self) -> list[Transition]:
        """The transitions since the last call (for publishing beside the rider frame)."""
        out, self._unpublished = self._unpublished, []
        return out
