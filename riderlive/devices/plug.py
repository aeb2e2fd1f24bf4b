"""What a device plugs into the lifecycle: its transport, its steps and its moves.

A :class:`Plug` knows one kind of hardware (a Dynamixel bus, a motion platform's
serial link) and nothing of states, operators or e-stops: :class:`~riderlive.devices.
device.Device` decides *whether* and *when*, the plug decides *how*. Every method is
one short piece of bus work, called from the thread that ticks; none sleeps.

- ``setup(detail)``: a generator that opens the transport (:class:`PortBusy` if another
  process holds it), checks every unit and configures it, one transaction per
  ``next()``, and leaves every output **off**. ``detail`` says which step it is on.
- ``arm()``: outputs on, holding the present pose: the soft start begins there.
- ``drive(frame, now, motion)``: one tick of ``motion`` (home, soft start, run, park):
  compute the goal from the tick's :class:`~riderlive.tickframe.TickFrame` (metres and
  degrees; the parts the plug's kind declares in ``DeviceInfo.consumes``; None when
  parking outside a tick: close, the guardian), write it inside ``self.stops.gate()``
  (so no goal leaves after an e-stop request), read back when due. True when the move is
  complete (homed, soft start over, parked and settled). Raises the lifecycle's errors.
- ``outputs_off()``: the fastest "everything off" the transport has, no reply awaited
  (a broadcast); ``outputs_confirmed_off()``: read back, True when every unit is off.
- ``on_fault(error)``: first aid for one unit (torque off the servo that reported an
  overload), before the others park.
- ``idle(now)``: every tick while the transport is open and nothing moves (disarmed,
  parked, e-stop, fault): keep a link alive that needs it, notice what the device did by
  itself (raise the lifecycle's errors, once per event). Most plugs do nothing.
- ``takeover(pose)``: the guardian opens a transport another process was driving,
  outputs assumed on at ``pose``; the next ``drive(PARK)`` eases from there.
- ``pose``: the last goal sent (device units), published for the guardian;
  ``park_timeout_s``: the longest a park may take before outputs go off regardless;
  ``status()``: what to publish besides the lifecycle (per-unit values); ``counters``.

Optional capabilities are part of the interface too, with defaults in :class:`PlugBase`
(a plug inherits them): ``goal_written_at`` / ``off_written_at`` (``perf_counter`` s the
last goal or outputs-off write returned; None: not tracked, the caller's clock stands
in), ``idle(now)`` (nothing by default) and ``tune(**changes)`` (live parameters:
:class:`NotTunable` by default).

Hardware-specific timing (soft start and park durations, slew limits, read dividers)
lives in the plug's own configuration.
"""

from __future__ import annotations

import enum
from collections import Counter
from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

from riderlive.devices.latch import StopView
from riderlive.tickframe import TickFrame

T = TypeVar("T")
Steps = Generator[None, None, T]
"""A piece of work spread over ticks: one transaction per ``next()``."""


class Move(enum.Enum):
    """What ``drive`` is asked to do on this tick."""

    HOME = "home"
    SOFT_START = "soft_start"
    RUN = "run"
    PARK = "park"


@dataclass(frozen=True, slots=True)
class Motion:
    """One tick of a move. Times in seconds."""

    move: Move
    elapsed: float
    """Since this move began (0 on its first tick)."""
    dt: float
    """Since the previous tick (0 on the first; bounded by a few periods)."""
    first: bool
    """The first tick of this move: take the present goal as the start of a ramp."""
    faulted: bool = False
    """Parking after a fault: skip what may fail again (reads), keep the goals going."""


class NotTunable(Exception):
    """The plug has no live parameters."""


class Plug(Protocol):
    """The narrow interface between one device and the lifecycle (see the module docstring)."""

    name: str
    kind: str
    stops: StopView | None
    needs_homing: bool
    counters: Counter[str]
    goal_written_at: float | None
    off_written_at: float | None

    @property
    def is_open(self) -> bool: ...

    @property
    def pose(self) -> Sequence[float]: ...

    @property
    def park_timeout_s(self) -> float: ...

    def setup(self, detail: Callable[[str], None]) -> Steps[None]: ...

    def close(self) -> None: ...

    def arm(self) -> None: ...

    def drive(self, frame: TickFrame | None, now: float, motion: Motion) -> bool: ...

    def outputs_off(self) -> None: ...

    def outputs_confirmed_off(self) -> bool: ...

    def on_fault(self, error: BaseException) -> None: ...

    def idle(self, now: float) -> None: ...

    def takeover(self, pose: Sequence[float]) -> None: ...

    def status(self) -> dict[str, Any]: ...

    def tune(self, **changes: Any) -> None: ...


class PlugBase:
    """The defaults of a plug's optional capabilities (see the module docstring)."""

    name: str
    goal_written_at: float | None = None
    off_written_at: float | None = None

    def idle(self, now: float) -> None:
        """Nothing to keep alive between the lifecycle's read-backs."""

    def tune(self, **changes: Any) -> None:
        raise NotTunable(f"{self.name} has no live parameters")


def smoothstep(x: float) -> float:
    """0 -> 0, 1 -> 1 with zero slope at both ends (soft-start and park ramps)."""
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


def ramp(start: Sequence[float], end: Sequence[float], elapsed: float, duration: float) -> tuple[list[float], bool]:
    """``start`` eased to ``end`` over ``duration`` seconds; (pose, arrived)."""
    alpha = smoothstep(elapsed / duration) if duration > 0 else 1.0
    return [s + alpha * (e - s) for s, e in zip(start, end, strict=True)], alpha >= 1.0
