"""An in-memory device for the lifecycle's own tests: units with outputs, goals, failures.

It follows the Plug contract (riderlive.devices.plug) literally: setup is a few steps
ending with outputs off, goals go through the latch's gate, a park ramps to 0 over
``park_s``. Failures are injected by setting ``fail_next`` (raised by the next call
to the named method). The hardware-facing behaviour is tested on the emulator
(tests/dynamixel); this exercises every transition and refusal of the state machine.
"""

from __future__ import annotations

import contextlib
from collections import Counter
from collections.abc import Callable, Sequence
from typing import Any

from riderlive.devices.latch import StopView
from riderlive.devices.plug import Motion, Move, PlugBase, Steps, ramp
from riderlive.tickframe import Flag, TickFrame


def rider_frame(*rider: float, tick: int = 0, at: float = 0.0) -> TickFrame:
    """A tick frame carrying only a rider (what the memory plug maps to its goals)."""
    return TickFrame.build(tick, at, at, at, Flag.PROCEDURAL, rider)


class MemoryPlug(PlugBase):
    kind = "memory"

    def __init__(self, name: str = "mem", units: int = 3, soft_start_s: float = 0.05, park_s: float = 0.05) -> None:
        self.name = name
        self.stops: StopView | None = None
        self.needs_homing = False
        self.counters: Counter[str] = Counter()
        self.units = units
        self.soft_start_s, self.park_s = soft_start_s, park_s
        self.open = False
        self.outputs = [True] * units  # whatever the last owner left on
        self.goals = [0.5] * units
        self.log: list[str] = []
        self.fail_next: dict[str, BaseException] = {}
        self.confirm = True
        self._from = list(self.goals)

    def _maybe_fail(self, what: str) -> None:
        error = self.fail_next.pop(what, None)
        if error is not None:
            raise error

    @property
    def is_open(self) -> bool:
        return self.open

    @property
    def pose(self) -> Sequence[float]:
        return self.goals

    @property
    def park_timeout_s(self) -> float:
        return self.park_s + 0.2

    def setup(self, detail: Callable[[str], None]) -> Steps[None]:
        detail("opening")
        self._maybe_fail("open")
        self.open = True
        yield
        detail("checking")
        self._maybe_fail("check")
        yield
        self.outputs = [False] * self.units
        self.log.append("setup")

    def close(self) -> None:
        self.open = False

    def arm(self) -> None:
        self._maybe_fail("arm")
        gate = self.stops.gate() if self.stops is not None else contextlib.nullcontext()
        with gate:
            self.outputs = [True] * self.units
        self.log.append("arm")

    def drive(self, frame: TickFrame | None, now: float, motion: Motion) -> bool:
        self._maybe_fail("drive")
        if motion.first:
            self._from = list(self.goals)
        target = [frame.rider[0] if frame is not None and frame.rider else 0.0] * self.units
        done = False
        if motion.move is Move.PARK:
            target, done = ramp(self._from, [0.0] * self.units, motion.elapsed, self.park_s)
        elif motion.move is Move.SOFT_START:
            target, done = ramp(self._from, target, motion.elapsed, self.soft_start_s)
        gate = self.stops.gate() if self.stops is not None else contextlib.nullcontext()
        with gate:
            self.goals = target
            self.counters["goal_writes"] += 1
        return done

    def outputs_off(self) -> None:
        self._maybe_fail("off")
        self.outputs = [False] * self.units
        self.log.append("off")

    def outputs_confirmed_off(self) -> bool:
        self._maybe_fail("confirm")
        return self.confirm and not any(self.outputs)

    def on_fault(self, error: BaseException) -> None:
        self.log.append(f"first aid: {type(error).__name__}")

    def idle(self, now: float) -> None:
        self._maybe_fail("idle")

    def takeover(self, pose: Sequence[float]) -> None:
        self.open = True
        self.goals = list(pose)

    def status(self) -> dict[str, Any]:
        return {"goals": list(self.goals), "outputs": list(self.outputs)}


def describe(file: str, port: str | None) -> Any:
    """The registry's hook (kind ``memory``): ``file`` is the device's name; 100 ticks/s."""
    from riderlive.devices.registry import DeviceInfo

    return DeviceInfo(file, 100.0, f"{file}: in memory")


def make_plug(spec: Any) -> MemoryPlug:
    return MemoryPlug(name=spec.name)
