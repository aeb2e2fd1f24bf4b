"""Bringing a rig up and arming it: connect, check, configure (torque off), torque on.

:func:`bring_up` is a generator that yields after every bus transaction, so the
device runner can spread it over ticks and an e-stop can cut in between any two of
them. A transaction that meets a silent servo is retried on later steps for
``setup_retry_s``; every other failure raises one of the lifecycle's errors. It ends
with every servo configured and its torque **off**: arming (:func:`torque_on_here`)
is a separate, operator-issued step.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from functools import partial
from typing import TypeVar

from riderlive.devices.lifecycle import HardwareFault, Mismatch, NoReply
from riderlive.devices.plug import Steps
from riderlive.dynamixel.models import ModelSpec
from riderlive.dynamixel.rig import RigConfig, ServoConfig
from riderlive.dynamixel.sdkbus import SdkBus, usb_latency_timer_ms
from riderlive.dynamixel.servo_map import (
    deg_to_pulses,
    profile_acceleration,
    profile_velocity,
    pulses_to_deg,
    return_delay_units,
    watchdog_units,
)
from riderlive.dynamixel.tables import ALERT_BIT, Item, ItemSpec, OperatingMode, decode_hardware_error

log = logging.getLogger("riderlive.dynamixel")
T = TypeVar("T")

EEPROM_FIRST, EEPROM_END = 9, 64
"""The EEPROM span configured here (Return Delay Time .. Shutdown), read in one go."""


def hardware_bits(raw: int) -> tuple[str, ...]:
    """Hardware Error Status (70) -> bit names, e.g. ``("overheating", "overload")``."""
    return tuple(str(bit.name).lower() for bit in decode_hardware_error(raw))


def servo_hardware_error(servo_id: int, raw: int) -> HardwareFault:
    return HardwareFault(servo_id, hardware_bits(raw), raw, what="servo")


def first_spec(rig: RigConfig) -> ModelSpec:
    """Every X-series model shares the addresses used for group transactions."""
    return next(iter(rig.servos.values())).spec


def bring_up(bus: SdkBus, rig: RigConfig, detail: Callable[[str], None]) -> Steps[None]:
    """Open the port, check every servo, configure it, torque off; one transaction per step."""
    budget = rig.bus.setup_retry_s
    detail(f"opening {rig.bus.port} at {rig.bus.baud} baud")
    bus.open()
    check_latency(bus, rig)
    spec = first_spec(rig)
    bus.broadcast_write(spec.spec(Item.TORQUE_ENABLE), 0)  # whatever the last owner left on
    yield
    detail("checking: ping, model number, hardware errors")
    for servo in rig.servos.values():
        found = yield from _retry(budget, partial(bus.ping, servo.id))
        if found != servo.spec.model_number:
            message = f"servo {servo.id}: model number {found}, the rig map expects {servo.spec.model_number}"
            raise Mismatch(servo.id, message)
        status = servo.spec.spec(Item.HARDWARE_ERROR_STATUS)
        yield from _check_hardware(bus, rig, servo.id, status)
    detail("configuring")
    for servo in rig.servos.values():
        yield from _configure(bus, rig, servo)
    if rig.bus.bus_watchdog_ms:
        arm_watchdog(bus, rig)  # it runs only while torque is on
        yield


def read_present(bus: SdkBus, rig: RigConfig, ids: tuple[int, ...]) -> tuple[list[float], list[int]]:
    """Present Position of ``ids`` (degrees), one plain Sync Read; and the ids whose
    status carried the Alert bit (a hardware error to read)."""
    position = first_spec(rig).spec(Item.PRESENT_POSITION)
    block = bus.read_block(position.address, position.size, ids, fast=False)
    present = [pulses_to_deg(int.from_bytes(block[sid][1], "little", signed=True)) for sid in ids]
    return present, [sid for sid in ids if block[sid][0] & ALERT_BIT]


def torque_on_here(bus: SdkBus, rig: RigConfig, ids: tuple[int, ...], present: list[float]) -> list[float]:
    """Arm: the goal is where the servos are (``present``, within the limits), torque on,
    the Bus Watchdog armed. Returns the goals (degrees, rig order): the soft start's start."""
    spec = first_spec(rig)
    servos = list(rig.servos.values())
    goals = [min(max(p, s.min_deg), s.max_deg) for p, s in zip(present, servos, strict=True)]
    bus.sync_write(spec.spec(Item.GOAL_POSITION), {s: deg_to_pulses(g) for s, g in zip(ids, goals, strict=True)})
    if rig.bus.bus_watchdog_ms:
        arm_watchdog(bus, rig)
    bus.sync_write(spec.spec(Item.TORQUE_ENABLE), dict.fromkeys(ids, 1))
    return goals


def arm_watchdog(bus: SdkBus, rig: RigConfig) -> None:
    """Clear a tripped Bus Watchdog (write 0), then arm it: two SYNC_WRITEs."""
    spec = first_spec(rig).spec(Item.BUS_WATCHDOG)
    bus.sync_write(spec, dict.fromkeys(rig.ids, 0))
    bus.sync_write(spec, dict.fromkeys(rig.ids, watchdog_units(rig.bus.bus_watchdog_ms)))


def check_latency(bus: SdkBus, rig: RigConfig) -> None:
    """Warn when an FTDI adapter's latency timer is above the rig map's, and use it."""
    actual = usb_latency_timer_ms(rig.bus.port)
    if actual is not None and actual > rig.bus.latency_timer_ms:
        log.warning(
            "%s: the adapter's latency timer is %d ms (rig map says %g): replies will be late; "
            "set it to 1 ms (docs/hardware.md). Using %d ms for reply timeouts.",
            rig.bus.port,
            actual,
            rig.bus.latency_timer_ms,
            actual,
        )
        bus.port.latency_ms = float(actual)


def _retry(budget_s: float, call: Callable[[], T]) -> Steps[T]:
    """One transaction, retried on later steps while the servo stays silent (up to
    ``budget_s``), then a yield."""
    first_failure: float | None = None
    while True:
        try:
            value = call()
            break
        except NoReply:
            now = time.perf_counter()
            first_failure = now if first_failure is None else first_failure
            if now - first_failure >= budget_s:
                raise
        yield
    yield
    return value


def _check_hardware(bus: SdkBus, rig: RigConfig, servo_id: int, status: ItemSpec) -> Steps[None]:
    """Refuse to start on a hardware error, or REBOOT the servo if the rig map says so."""
    budget = rig.bus.setup_retry_s
    raw = yield from _retry(budget, partial(bus.read, servo_id, status))
    if raw and rig.bus.reboot_on_error:
        log.warning("servo %d reports %s: rebooting it", servo_id, hardware_bits(raw))
        yield from _retry(budget, partial(bus.reboot, servo_id))
        yield from _retry(budget, partial(bus.ping, servo_id))
        raw = yield from _retry(budget, partial(bus.read, servo_id, status))
    if raw:
        raise servo_hardware_error(servo_id, raw)


def _configure(bus: SdkBus, rig: RigConfig, servo: ServoConfig) -> Steps[None]:
    """Torque off, settings, profiles; the goal set to the present position (within the
    limits), so a later torque-on does not jump."""
    budget = rig.bus.setup_retry_s
    sid, spec = servo.id, servo.spec
    write, read = partial(bus.write, sid), partial(bus.read, sid)
    yield from _retry(budget, partial(write, spec.spec(Item.TORQUE_ENABLE), 0))
    yield from _retry(budget, partial(write, spec.spec(Item.BUS_WATCHDOG), 0))  # also clears a tripped one
    wanted = {
        Item.RETURN_DELAY_TIME: return_delay_units(rig.bus.return_delay_us),
        Item.DRIVE_MODE: 0,  # velocity-based profile, normal direction (direction is the map's)
        Item.OPERATING_MODE: int(OperatingMode.POSITION),
        Item.HOMING_OFFSET: 0,  # zero_deg in the rig map is the only trim
        Item.MAX_POSITION_LIMIT: deg_to_pulses(servo.max_deg),
        Item.MIN_POSITION_LIMIT: deg_to_pulses(servo.min_deg),
        Item.SHUTDOWN: rig.bus.shutdown_mask,
    }
    eeprom = yield from _retry(budget, partial(bus.read_raw, sid, EEPROM_FIRST, EEPROM_END - EEPROM_FIRST))
    for item, value in wanted.items():  # EEPROM wears: write only what differs
        item_spec = spec.spec(item)
        at = item_spec.address - EEPROM_FIRST
        if int.from_bytes(eeprom[at : at + item_spec.size], "little", signed=item_spec.signed) != value:
            yield from _retry(budget, partial(write, item_spec, value))
    accel = profile_acceleration(servo.max_accel_dps2)
    yield from _retry(budget, partial(write, spec.spec(Item.PROFILE_ACCELERATION), accel))
    yield from _retry(budget, partial(write, spec.spec(Item.PROFILE_VELOCITY), profile_velocity(servo.max_speed_dps)))
    present = pulses_to_deg((yield from _retry(budget, partial(read, spec.spec(Item.PRESENT_POSITION)))))
    start = min(max(present, servo.min_deg), servo.max_deg)
    yield from _retry(budget, partial(write, spec.spec(Item.GOAL_POSITION), deg_to_pulses(start)))
