"""Helpers for driving the rig device against the emulated bus (tests and bench share them)."""

from __future__ import annotations

import contextlib
import re
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from riderlive.channels import RIDER
from riderlive.devices.device import Device
from riderlive.devices.lifecycle import DeviceState
from riderlive.devices.status import DeviceStatus
from riderlive.dynamixel.driver import RigPlug
from riderlive.dynamixel.emulator import EmulatedBus, ServoSetup
from riderlive.dynamixel.rig import RigConfig, load_rig
from riderlive.dynamixel.tables import BROADCAST_ID, Instruction, Item
from tests.children import popen
from tests.devices.memory_plug import rider_frame

TORQUE_ENABLE_ADDRESS = 64


def servo_setups(rig: RigConfig) -> list[ServoSetup]:
    """One emulated servo per rig servo, horn in the middle (2048 pulses = 180 deg)."""
    return [ServoSetup(s.id, s.model) for s in rig.servos.values()]


def short_rig(name: str = "full_rider", **bus: Any) -> RigConfig:
    """A shipped rig with short ramps and a few bus settings changed for tests."""
    rig = load_rig(name)
    changes: dict[str, Any] = {
        "soft_start_s": 0.3,
        "park_s": 0.3,
        # a loaded 2-core CI box: generous timeouts, budgets and watchdog unless a test sets them
        "timeout_margin_ms": 40.0,
        "reply_budget_s": 0.3,
        "bus_watchdog_ms": 600,
    } | bus
    return RigConfig.model_validate(rig.model_dump() | {"bus": rig.bus.model_dump() | changes})


def is_torque_off_write(raw: bytes) -> bool:
    """Torque Enable = 0 for every servo: a broadcast WRITE, or a SYNC_WRITE of zeros."""
    if len(raw) == 13 and raw[4] == BROADCAST_ID and raw[7] == Instruction.WRITE:
        return (raw[8] | raw[9] << 8) == TORQUE_ENABLE_ADDRESS and raw[10] == 0
    if len(raw) < 14 or raw[7] != Instruction.SYNC_WRITE:
        return False
    address = raw[8] | raw[9] << 8
    length = raw[10] | raw[11] << 8
    return address == TORQUE_ENABLE_ADDRESS and length == 1 and not any(raw[13:-2:2])


class TimedBus(EmulatedBus):
    """The emulator, also noting when a torque-off packet has fully arrived (perf_counter s)."""

    torque_off_at: float | None = None

    def _handle(self, raw: bytes, arrived: float) -> None:
        if self.torque_off_at is None and is_torque_off_write(raw):
            wire = len(raw) * 10 / self.baud if self.wire_timing else 0.0
            self.torque_off_at = max(arrived, self._bus_free_at) + wire
        super()._handle(raw, arrived)


@dataclass
class Run:
    """Statuses of a paced run and the rider frames that went in."""

    statuses: list[DeviceStatus] = field(default_factory=list)
    riders: list[list[float]] = field(default_factory=list)
    overruns: int = 0


def plug_of(device: Device) -> RigPlug:
    assert isinstance(device.plug, RigPlug)
    return device.plug


def rig_of(device: Device) -> RigConfig:
    return plug_of(device).config


def drive(
    device: Device,
    seconds: float,
    rider: Callable[[float], Sequence[float]] | None = None,
    *,
    until: Callable[[DeviceStatus], bool] | None = None,
    hz: float | None = None,
    run: Run | None = None,
) -> Run:
    """Call ``tick`` at ``hz`` (the rig's tick_hz) on perf_counter deadlines."""
    run = run or Run()
    period = 1.0 / (hz or rig_of(device).bus.tick_hz)
    neutral = [0.0] * len(RIDER)
    start = next_tick = time.perf_counter()
    while time.perf_counter() - start < seconds:
        now = time.perf_counter()
        frame = list(rider(now - start)) if rider else neutral
        status = device.tick(rider_frame(*frame), now)
        run.statuses.append(status)
        run.riders.append(frame)
        if until is not None and until(status):
            break
        next_tick += period
        late = time.perf_counter() - next_tick
        if late > 0:
            run.overruns += 1
            next_tick = time.perf_counter()
        else:
            time.sleep(-late)
    return run


def connect(device: Device, timeout: float = 5.0) -> Run:
    """connect() and tick until disarmed (assert it gets there)."""
    device.connect("test")
    run = drive(device, timeout, until=lambda s: s.state is not DeviceState.CONNECTING)
    assert device.state is DeviceState.DISARMED, device.fault
    return run


def start_running(device: Device, rider: Callable[[float], Sequence[float]] | None = None, timeout: float = 5.0) -> Run:
    """Connect, arm, and tick until RUNNING (assert it gets there)."""
    run = connect(device, timeout)
    device.arm(device.name, "test")
    stop = (DeviceState.RUNNING, DeviceState.FAULT, DeviceState.ESTOP)
    run = drive(device, timeout, rider, until=lambda s: s.state in stop, run=run)
    assert device.state is DeviceState.RUNNING, run.statuses[-1].fault
    return run


def torque(bus: EmulatedBus, servo_id: int) -> int:
    return bus.read_item(servo_id, Item.TORQUE_ENABLE)


def goal_deg(status: DeviceStatus) -> list[float]:
    return [s["goal_deg"] for s in status.extra["servos"]]


def present_deg(status: DeviceStatus) -> list[float | None]:
    return [s["present_deg"] for s in status.extra["servos"]]


@contextlib.contextmanager
def servo_emulator(rig_file: Path) -> Iterator[str]:
    """``riderlive servo-emu --rig FILE --realtime 60`` in its own process (as a user would
    start it); yields its pty, stops it on the way out. At SCHED_FIFO where the host allows
    it: it stands for servos, which a busy host cannot starve (a -n 2 run beside two busy
    loops starved three normal-priority emulators of one stage into no-reply faults)."""
    root = Path(__file__).resolve().parents[2]
    emu = popen(
        [sys.executable, "-m", "riderlive", "servo-emu", "--rig", str(rig_file), "--realtime", "60"],
        stdout=subprocess.PIPE,
        text=True,
        env={"PYTHONPATH": str(root), "PATH": "/usr/bin:/bin"},
    )
    try:
        assert emu.stdout is not None
        yield next(m.group(1) for line in emu.stdout if (m := re.match(r"port: (\S+)", line)))
    finally:
        emu.terminate()
        emu.wait(10)
