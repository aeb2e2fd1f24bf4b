"""Every fault of the rig through the real SDK against the emulated bus, with its timing.

What each fault must do (docs/hardware.md, "Faults"):

- e-stop: torque-off SYNC_WRITE on the wire within one tick; ESTOP latched until reset().
- hardware error: that servo torqued off, the rest park, then FAULT with id and bits.
- silent servo: retried up to ``reply_budget_s``, then fault with its id, park, FAULT.
- port vanishes: FAULT at once; tick() keeps answering; reconnect() brings it back.
- ticks stop: the servos' Bus Watchdog stops them; the next tick re-arms it and parks.
- a hardware error or a wrong model at start: refuse to start (or reboot, if configured).
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from riderlive.channels import RIDER
from riderlive.dynamixel.driver import RigDriver
from riderlive.dynamixel.emulator import ServoSetup
from riderlive.dynamixel.emulator_faults import FaultKind as EmuFault
from riderlive.dynamixel.emulator_faults import FaultSpec
from riderlive.dynamixel.lifecycle import FaultKind, RigState
from riderlive.dynamixel.rig import RigConfig, pulses_to_deg
from riderlive.dynamixel.tables import HardwareError, Item
from tests.dynamixel.rig_harness import TimedBus, drive, servo_setups, short_rig, start_running, torque

NEUTRAL = [0.0] * len(RIDER)


@pytest.fixture
def timed_buses(fast_switching: None) -> Iterator[Callable[..., TimedBus]]:
    """TimedBus instances (emulators that note the torque-off packet); stopped at teardown."""
    buses: list[TimedBus] = []

    def make(servos: list[ServoSetup], **options: Any) -> TimedBus:
        bus = TimedBus(servos, **options).start()
        buses.append(bus)
        return bus

    yield make
    for bus in buses:
        bus.stop()


def rig_on(timed_buses: Callable[..., TimedBus], name: str = "bench3", **bus: Any) -> tuple[RigDriver, TimedBus]:
    rig = short_rig(name, **bus)
    emu = timed_buses(servo_setups(rig), baud=rig.bus.baud)
    return RigDriver(rig, port=emu.port), emu


def tick_until(driver: RigDriver, done: Callable[[RigState], bool], seconds: float = 3.0) -> float:
    """Tick (neutral rider) until ``done(state)``; return when it happened (perf_counter)."""
    run = drive(driver, seconds, until=lambda s: done(s.state))
    assert done(driver.state), f"still {driver.state}, fault {driver.fault}"
    return run.statuses[-1].at


# --- e-stop -----------------------------------------------------------------------------


def test_estop_torques_off_within_one_tick(timed_buses: Callable[..., TimedBus]) -> None:
    driver, emu = rig_on(timed_buses)
    start_running(driver)
    drive(driver, 0.2)
    pressed = time.perf_counter()
    driver.estop()
    emu.settle()
    assert emu.torque_off_at is not None
    latency = emu.torque_off_at - pressed
    assert latency < driver.config.bus.tick_s, f"e-stop to torque-off write took {latency * 1000:.1f} ms"
    assert driver.state is RigState.ESTOP
    assert all(torque(emu, i) == 0 for i in (1, 2, 3))

    # latched: the next tick repeats the torque-off broadcast, then nothing is sent;
    # open() cannot restart it, reset() does
    packets = emu.stats.packets
    statuses = drive(driver, 0.1).statuses
    emu.settle()
    assert all(s.state is RigState.ESTOP and not s.wrote for s in statuses)
    assert emu.stats.packets == packets + 1
    assert not driver.open()
    assert driver.reset()
    tick_until(driver, lambda s: s is RigState.RUNNING)


def test_estop_from_another_thread_during_ticks(timed_buses: Callable[..., TimedBus]) -> None:
    driver, emu = rig_on(timed_buses, tick_hz=100.0)
    start_running(driver)
    pressed: list[float] = []

    def press() -> None:
        time.sleep(0.137)
        pressed.append(time.perf_counter())
        driver.estop()

    presser = threading.Thread(target=press)
    presser.start()
    drive(driver, 0.4)
    presser.join()
    emu.settle()
    assert driver.state is RigState.ESTOP
    assert emu.torque_off_at is not None
    assert emu.torque_off_at - pressed[0] < driver.config.bus.tick_s + 0.001


def test_estop_during_setup(timed_buses: Callable[..., TimedBus]) -> None:
    driver, emu = rig_on(timed_buses, "full_rider", baud=4_000_000)
    driver.open()
    drive(driver, 2.0, until=lambda s: s.state is RigState.CONFIGURING)
    driver.estop()
    assert driver.state is RigState.ESTOP
    emu.settle()
    assert all(torque(emu, i) == 0 for i in range(1, 25))
    assert drive(driver, 0.1).statuses[-1].state is RigState.ESTOP  # the setup does not resume


# --- servo hardware errors --------------------------------------------------------------


@pytest.mark.parametrize(
    ("kind", "bit"),
    [(EmuFault.OVERLOAD, "overload"), (EmuFault.OVERHEAT, "overheating"), (EmuFault.VOLTAGE, "input_voltage")],
)
def test_hardware_error_parks_and_reports(timed_buses: Callable[..., TimedBus], kind: EmuFault, bit: str) -> None:
    driver, emu = rig_on(timed_buses)
    start_running(driver)
    drive(driver, 0.1)
    injected = time.perf_counter()
    emu.apply(FaultSpec(kind, 2))
    detected = tick_until(driver, lambda s: s is not RigState.RUNNING)
    bus = driver.config.bus
    # found on the next divided read: within read_divider ticks (+ one tick of slack)
    assert detected - injected <= (bus.read_divider + 1) * bus.tick_s + 0.05
    assert driver.state is RigState.PARKING
    fault = driver.fault
    assert fault is not None and fault.kind is FaultKind.HARDWARE_ERROR
    assert fault.servo_id == 2 and bit in fault.bits
    assert torque(emu, 2) == 0
    status = driver.tick(NEUTRAL, time.perf_counter())
    assert status.hardware_errors == {2: fault.bits}
    assert status.to_dict()["fault"]["bits"] == list(fault.bits)

    off = tick_until(driver, lambda s: s is RigState.FAULT)
    emu.settle()
    # eased to park, waited for the servos to arrive, then torque off
    assert bus.park_s - bus.tick_s <= off - detected <= bus.park_s + bus.park_settle_s + 0.3
    assert all(torque(emu, i) == 0 for i in (1, 2, 3))
    head_park = driver.config.servos["head"].park
    assert abs(pulses_to_deg(emu.read_item(3, Item.GOAL_POSITION)) - head_park) < 0.1


def test_hardware_error_at_start_refuses_or_reboots(timed_buses: Callable[..., TimedBus]) -> None:
    driver, emu = rig_on(timed_buses)
    emu.write_item(3, Item.HARDWARE_ERROR_STATUS, int(HardwareError.OVERLOAD))
    driver.open()
    tick_until(driver, lambda s: s is RigState.FAULT)
    fault = driver.fault
    assert fault is not None and fault.kind is FaultKind.HARDWARE_ERROR and fault.servo_id == 3
    assert fault.bits == ("overload",)
    emu.settle()
    assert all(torque(emu, i) == 0 for i in (1, 2, 3))

    rebooting, emu2 = rig_on(timed_buses, reboot_on_error=True)
    emu2.write_item(3, Item.HARDWARE_ERROR_STATUS, int(HardwareError.OVERLOAD))
    start_running(rebooting)
    assert emu2.stats.instructions["REBOOT"] == 1
    assert emu2.read_item(3, Item.HARDWARE_ERROR_STATUS) == 0


def test_wrong_model_refuses_to_start(timed_buses: Callable[..., TimedBus]) -> None:
    rig = short_rig("bench3")
    emu = timed_buses([ServoSetup(1, "XL330-M288"), ServoSetup(2, "XL430-W250"), ServoSetup(3, "XL330-M288")])
    driver = RigDriver(rig, port=emu.port)
    driver.open()
    tick_until(driver, lambda s: s is RigState.FAULT)
    fault = driver.fault
    assert fault is not None and fault.kind is FaultKind.MODEL_MISMATCH and fault.servo_id == 2
    assert "1060" in fault.message and "1200" in fault.message


# --- silent servos ---------------------------------------------------------------------


def test_silent_servo_faults_after_budget_then_parks(timed_buses: Callable[..., TimedBus]) -> None:
    driver, emu = rig_on(timed_buses, "full_rider", baud=4_000_000, reply_budget_s=0.25, tick_hz=50.0)
    start_running(driver)
    drive(driver, 0.2)
    vanished = time.perf_counter()
    emu.apply(FaultSpec(EmuFault.VANISH, 7))
    detected = tick_until(driver, lambda s: s is not RigState.RUNNING)
    bus = driver.config.bus
    fault = driver.fault
    assert fault is not None and fault.kind is FaultKind.NO_REPLY and fault.servo_id == 7
    took = detected - vanished
    # silent for reply_budget_s since its last answer (at most one read period before it
    # vanished), retried every tick meanwhile; then the fault
    read_period = bus.read_divider * bus.tick_s
    assert bus.reply_budget_s - read_period <= took <= bus.reply_budget_s + read_period + 0.2
    assert driver.state is RigState.PARKING
    tick_until(driver, lambda s: s is RigState.FAULT)
    emu.settle()
    assert all(torque(emu, i) == 0 for i in range(1, 25) if i != 7)
    # servo 7 heard nothing since it vanished: its own Bus Watchdog has stopped it
    time.sleep(bus.bus_watchdog_ms / 1000)
    emu.apply(FaultSpec(EmuFault.REAPPEAR, 7))
    assert emu.read_item(7, Item.BUS_WATCHDOG) == -1


def test_transient_drops_are_retried_without_fault(timed_buses: Callable[..., TimedBus]) -> None:
    driver, emu = rig_on(timed_buses, fast_read_fallback_after=2)
    start_running(driver)
    emu.apply(FaultSpec(EmuFault.DROP, 2, count=1))
    run = drive(driver, 0.3)
    emu.apply(FaultSpec(EmuFault.DROP, 2, count=1))
    run = drive(driver, 0.3, run=run)
    last = run.statuses[-1]
    assert last.state is RigState.RUNNING and last.fault is None
    # each drop failed one Fast Sync Read (a loaded box may time out one more)
    assert last.counters["fast_read_failures"] >= 2
    assert not last.fast_sync_read  # fell back to plain Sync Read after 2 fast failures
    more = drive(driver, 0.3).statuses[-1]
    assert more.counters["fast_read_failures"] == last.counters["fast_read_failures"]  # no fast read since
    assert more.counters["reads"] > last.counters["reads"]


def test_old_firmware_without_fast_read_falls_back(timed_buses: Callable[..., TimedBus]) -> None:
    rig = short_rig("bench3", fast_read_fallback_after=3)
    setups = servo_setups(rig)
    setups[1] = ServoSetup(setups[1].id, setups[1].model, fast_read=False)  # ignores FAST_SYNC_READ
    emu = timed_buses(setups, baud=rig.bus.baud)
    driver = RigDriver(rig, port=emu.port)
    start_running(driver)
    last = drive(driver, 3.0, until=lambda s: not s.fast_sync_read).statuses[-1]
    assert not last.fast_sync_read
    assert last.state is RigState.RUNNING and last.fault is None
    assert last.counters["fast_read_failures"] == 3
    reads = last.counters["reads"]
    last = drive(driver, 0.3).statuses[-1]
    assert last.counters["reads"] > reads and last.counters["fast_read_failures"] == 3
    assert all(p is not None for p in last.present_deg)


# --- the port and the ticks -------------------------------------------------------------


def test_port_vanishes_then_reconnects(timed_buses: Callable[..., TimedBus], tmp_path: Path) -> None:
    rig = short_rig("bench3")
    link = tmp_path / "ttyRIG"  # a stable name, like /dev/serial/by-id/...
    emu = timed_buses(servo_setups(rig), baud=rig.bus.baud)
    os.symlink(emu.port, link)
    driver = RigDriver(rig, port=str(link))
    start_running(driver)
    drive(driver, 0.1)
    pulled = time.perf_counter()
    emu.close_port()
    failed = tick_until(driver, lambda s: s is RigState.FAULT, seconds=1.0)
    assert failed - pulled < 2 * driver.config.bus.tick_s + 0.05
    fault = driver.fault
    assert fault is not None and fault.kind is FaultKind.PORT_LOST
    statuses = drive(driver, 0.1).statuses  # tick() goes on answering
    assert all(s.state is RigState.FAULT and s.transactions == 0 for s in statuses)

    emu2 = timed_buses(servo_setups(rig), baud=rig.bus.baud)  # plugged back in
    link.unlink()
    os.symlink(emu2.port, link)
    assert driver.reconnect()
    tick_until(driver, lambda s: s is RigState.RUNNING)
    assert driver.fault is None


def test_stalled_ticks_trip_the_watchdog_then_park(timed_buses: Callable[..., TimedBus]) -> None:
    driver, emu = rig_on(timed_buses, bus_watchdog_ms=300)
    rider = list(NEUTRAL)
    rider[RIDER.index(next(c for c in RIDER if c.name == "hip.ry"))] = 15.0
    start_running(driver)
    drive(driver, 0.05, lambda t: rider)  # servo 2 starts moving toward 210 deg
    time.sleep(0.7)  # the service hangs
    assert emu.read_item(2, Item.BUS_WATCHDOG) == -1  # the servos stopped themselves
    stopped_at = emu.position(2)
    time.sleep(0.05)
    assert emu.position(2) == pytest.approx(stopped_at, abs=1.0)
    drive(driver, 0.5, lambda t: rider, until=lambda s: s.state is not RigState.RUNNING)
    fault = driver.fault
    assert fault is not None and fault.kind is FaultKind.TICK_GAP
    assert driver.state is RigState.PARKING
    emu.settle()
    assert emu.read_item(2, Item.BUS_WATCHDOG) == 15  # re-armed (300 ms), goals writable again
    tick_until(driver, lambda s: s is RigState.FAULT)
    emu.settle()
    assert abs(pulses_to_deg(emu.read_item(2, Item.GOAL_POSITION)) - driver.config.servos["hips"].park) < 0.1


def test_tick_never_raises_without_a_port() -> None:
    rig: RigConfig = short_rig("bench3").with_port("/nonexistent/ttyUSB9")
    driver = RigDriver(rig)
    driver.open()
    status = driver.tick(NEUTRAL, time.perf_counter())
    assert status.state is RigState.FAULT
    assert status.fault is not None and status.fault.kind is FaultKind.PORT_LOST
    assert "/nonexistent/ttyUSB9" in status.fault.message
    for _ in range(3):
        assert driver.tick(NEUTRAL, time.perf_counter()).state is RigState.FAULT
    driver.close()
    assert driver.state is RigState.CLOSED
