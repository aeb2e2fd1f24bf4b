"""The Dynamixel rig as a device: the plug that puts a servo bus into the one lifecycle.

:class:`RigPlug` is what :class:`~riderlive.devices.device.Device` drives (see
:mod:`riderlive.devices.plug`): the setup is :mod:`~riderlive.dynamixel.bringup`
(connect, check, configure, torque off), arming reads where the servos are and turns
torque on there, and each tick of motion is one goal SYNC_WRITE (inside the e-stop
latch's gate) plus, every ``read_divider`` ticks, the divided read of
:mod:`~riderlive.dynamixel.readback`. Outputs off is Torque Enable 0 to the broadcast
ID (13 bytes, every servo on the bus, mapped or not); its read-back is a Sync Read of
Torque Enable.

The steady goal stream also feeds the servos' Bus Watchdog: when it stops (a dead or
frozen controller, a pulled cable) the servos stop by themselves after
``bus_watchdog_ms``, **but keep their torque on** (X-series e-manual): the guardian
process (:mod:`riderlive.devices.guardian`) is what parks and releases them.

:func:`rig_device` builds the Device: ``rig_device(load_rig("bench3"), port)``.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections import Counter
from collections.abc import Callable, Sequence
from typing import Any

from riderlive.channels import RIDER
from riderlive.devices.budget import ReplyTimer
from riderlive.devices.device import Device
from riderlive.devices.iowait import IoWait
from riderlive.devices.latch import StopLatch, StopView
from riderlive.devices.lifecycle import DeviceError, HardwareFault, NoReply, Rejected, TickGap
from riderlive.devices.plug import Motion, Move, PlugBase, Steps, ramp
from riderlive.devices.registry import DeviceInfo, DeviceSpec
from riderlive.devices.stall import usable_between
from riderlive.dynamixel.bringup import arm_watchdog, bring_up, first_spec, read_present, torque_on_here
from riderlive.dynamixel.readback import Readback, raise_hardware_error
from riderlive.dynamixel.rig import RigConfig, load_rig, longest_tick_wait_s, wire_budget
from riderlive.dynamixel.sdkbus import SdkBus
from riderlive.dynamixel.servo_map import ServoMap, deg_to_pulses
from riderlive.dynamixel.tables import Item
from riderlive.tickframe import TickFrame

TAKEOVER_QUIET_S = 0.012
"""After taking over a bus whose writer died mid-packet: silence longer than a servo's
partial-packet timeout (the emulator's 10 ms; the e-manual's 1.5 ms) so the first
packet is parsed whole."""


class RigPlug(PlugBase):
    """One Dynamixel bus of a rig map (``config/rigs/*.toml``); see the module docstring."""

    kind = "dynamixel"
    needs_homing = False

    def __init__(self, config: RigConfig, port: str | None = None, period_s: float | None = None) -> None:
        self.config = config if port is None else config.with_port(port)
        bus = self.config.bus
        self.name = self.config.name
        self.period_s = bus.tick_s if period_s is None else period_s
        self.map = ServoMap(self.config)
        self._spec = first_spec(self.config)
        self.timer = ReplyTimer(floor_ms=bus.timeout_margin_ms, ceiling_ms=bus.max_reply_wait_ms)
        self.bus = SdkBus(bus.port, bus.baud, bus.latency_timer_ms, self.timer)
        self.readback = Readback(self.config)
        self.counters: Counter[str] = Counter()
        self._stops: StopView | None = None
        n = len(self.map)
        self.goals: list[float] = list(self.map.park)
        self.clamped: list[bool] = [False] * n
        self.goal_written_at: float | None = None
        """perf_counter time the last goal SYNC_WRITE returned (handed to the port)."""
        self.goal_begun_at: float | None = None
        """perf_counter time the last goal SYNC_WRITE began (its write system call; in the e-stop record)."""
        self.off_written_at: float | None = None
        """perf_counter time the last outputs-off write returned (the first, if written twice)."""
        self.tracking: list[float | None] = [None] * n
        self.hardware_errors: dict[int, tuple[str, ...]] = {}
        self.disabled: set[int] = set()
        self._ramp_from: list[float] = list(self.goals)
        self._park_goals_at: float | None = None
        self._last_read: float | None = None
        self._since_read = 0
        self._watchdog_armed = False
        self.read_this_tick = False

    # -- the Plug interface -------------------------------------------------------------

    @property
    def stops(self) -> StopView | None:
        return self._stops

    @stops.setter
    def stops(self, view: StopView | None) -> None:
        self._stops = view
        self.bus.port.stops = view

    @property
    def io_wait(self) -> IoWait | None:
        """Where the bus declares its reply waits (the tick's board; ``devices/iowait.py``)."""
        return self.bus.port.io_wait

    @io_wait.setter
    def io_wait(self, declare: IoWait | None) -> None:
        self.bus.port.io_wait = declare

    @property
    def is_open(self) -> bool:
        return self.bus.is_open

    @property
    def pose(self) -> Sequence[float]:
        return self.goals

    @property
    def park_timeout_s(self) -> float:
        bus = self.config.bus
        return bus.park_s + 2.0 * self.period_s  # the wait for arrival is inside park_s (rig.BusConfig)

    def setup(self, detail: Callable[[str], None]) -> Steps[None]:
        self.hardware_errors.clear()
        self.disabled.clear()
        self.readback.restart()
        self._watchdog_armed = False
        yield from bring_up(self.bus, self.config, detail)

    def close(self) -> None:
        self.bus.close()
        self._watchdog_armed = False

    def arm(self) -> None:
        """Torque on where the servos are. A transient miss is retried (within the reply
        budget); a servo shut down by a hardware error would ignore torque-on: refused."""
        ids = self.map.ids
        spec = self._spec.spec(Item.HARDWARE_ERROR_STATUS)
        host = self.readback.host
        started = host.sample(time.perf_counter())
        while True:
            try:
                present, alerts = read_present(self.bus, self.config, ids)
                break
            except NoReply:
                self.counters["arm_retries"] += 1  # the budget is usable time, as the read's (devices/stall.py)
                if usable_between(started, host.sample(time.perf_counter())) > self.config.bus.reply_budget_s:
                    raise
        for sid in alerts:
            raise_hardware_error(self.bus, sid, spec)
        with self._gate():
            self.goals = torque_on_here(self.bus, self.config, ids, present)
        self._arm_state()

    def drive(self, frame: TickFrame | None, now: float, motion: Motion) -> bool:
        bus = self.config.bus
        self.read_this_tick = False
        if motion.first:
            self._ramp_from, self._park_goals_at = list(self.goals), None
        self._check_gap(now, motion)
        arrived = False
        if motion.move is Move.PARK:
            targets, arrived = ramp(self._ramp_from, self.map.park, motion.elapsed, bus.park_ramp_s)
        else:
            targets = self.map.targets(self._valid(() if frame is None else frame.rider), self.goals)
            if motion.move is Move.SOFT_START:
                targets, arrived = ramp(self._ramp_from, targets, motion.elapsed, bus.soft_start_s)
        goals, clamped = self.map.limit(targets, self.goals, motion.dt)
        pulses = {sid: deg_to_pulses(g) for sid, g in zip(self.map.ids, goals, strict=True) if sid not in self.disabled}
        with self._gate():
            self.bus.sync_write(self._spec.spec(Item.GOAL_POSITION), pulses)
        self.goal_written_at = time.perf_counter()
        self.goal_begun_at = self.bus.port.last_write  # stamped as the packet's write began, before the latch's check
        self.goals, self.clamped = goals, clamped
        self.counters["goal_writes"] += 1
        self.counters["clamps"] += sum(clamped)
        self._read_if_due(now, motion)
        if motion.move is Move.PARK:
            return arrived and self._parked(goals, now)
        return arrived and motion.move is Move.SOFT_START

    def outputs_off(self) -> None:
        """Torque Enable 0 to the broadcast ID, at once. After an e-stop gave up a read, the
        servo's late reply may still be on the half-duplex line and garble this first
        write: it is then written again once the line is quiet (the read-back that follows
        repeats it until every servo reports off)."""
        torque = self._spec.spec(Item.TORQUE_ENABLE)
        again = self.bus.unsettled
        self.bus.broadcast_write(torque, 0, settle=False)
        self.off_written_at = time.perf_counter()
        self.counters["torque_off_writes"] += 1
        if again:
            self.bus.broadcast_write(torque, 0)
            self.counters["torque_off_writes"] += 1
            self.counters["torque_off_rewrites"] += 1

    def outputs_confirmed_off(self) -> bool:
        torque = self._spec.spec(Item.TORQUE_ENABLE)
        try:
            block = self.bus.read_block(torque.address, torque.size, self.map.ids, fast=False)
        except (NoReply, Rejected):
            self.counters["off_unconfirmed"] += 1
            return False
        return all(data[0] == 0 for _, data in block.values())

    def on_fault(self, error: BaseException) -> None:
        """A servo that reported a hardware error: torque it off, leave it out of goals and reads."""
        if isinstance(error, HardwareFault) and error.unit in self.map.ids:
            self.hardware_errors[error.unit] = error.bits
            self.disabled.add(error.unit)
            self.bus.write(error.unit, self._spec.spec(Item.TORQUE_ENABLE), 0)

    def idle(self, now: float) -> None:
        """Nothing between the lifecycle's read-backs: the bus needs no keep-alive."""

    def takeover(self, pose: Sequence[float]) -> None:
        """Open a bus another process drove (it is dead), clear and re-arm the watchdog
        (a tripped one refuses goals), and take ``pose`` as the last goals."""
        self.bus.open()
        time.sleep(TAKEOVER_QUIET_S)
        self.goals = list(pose) if len(pose) == len(self.map) and all(map(math.isfinite, pose)) else list(self.map.park)
        if self.config.bus.bus_watchdog_ms:
            with self._gate():
                arm_watchdog(self.bus, self.config)
        self._arm_state()

    def status(self) -> dict[str, Any]:
        """Per servo (rig order): goal sent, clamped, present, tracking error, temperature,
        voltage, hardware error; and the bus: fast read, reply timer, transactions."""
        rb = self.readback
        servos = [
            {
                "name": name,
                "id": sid,
                "goal_deg": self.goals[i],
                "clamped": self.clamped[i],
                "present_deg": rb.present_deg[i],
                "tracking_error_deg": self.tracking[i],
                "temperature_c": rb.temperature_c[i],
                "voltage_v": rb.voltage_v[i],
                "hardware_error": list(self.hardware_errors.get(sid, ())),
            }
            for i, (name, sid) in enumerate(zip(self.map.names, self.map.ids, strict=True))
        ]
        return {
            "servos": servos,
            "clamps": sum(self.clamped),
            "read": self.read_this_tick,
            "fast_sync_read": rb.use_fast,
            "reply_allowance_ms": {k: round(t.allowance_ms(), 3) for k, t in self.bus.timers.items()},
            "bus_error_level": rb.budget.level,
            "silent_ms": {str(sid): {"charged": c, "host_stalled": h} for sid, (c, h) in rb.silent.items()},
            "transactions": self.bus.transactions,
        }

    # -- inside ---------------------------------------------------------------------------

    def _gate(self) -> Any:
        if self._stops is None:
            return contextlib.nullcontext()
        return self._stops.gate()

    def _arm_state(self) -> None:
        self.readback.restart()
        self._watchdog_armed = bool(self.config.bus.bus_watchdog_ms)
        self._since_read = 0
        self._last_read = None

    def _valid(self, frame: Sequence[float]) -> Sequence[float]:
        """A rider frame (m, deg) of the wrong length or with non-finite values holds the goals."""
        if len(frame) == len(RIDER) and all(map(math.isfinite, frame)):
            return frame
        self.counters["bad_inputs"] += 1
        return frame if len(frame) == len(RIDER) else [math.nan] * len(RIDER)

    def _check_gap(self, now: float, motion: Motion) -> None:
        """Ticks stopped for longer than the Bus Watchdog: it has tripped (the servos stopped
        and refuse goals). Re-arm it; unless already parking, that is a fault."""
        watchdog_s = self.config.bus.bus_watchdog_ms / 1000.0
        last = self.bus.port.last_write
        if not (self._watchdog_armed and watchdog_s and last is not None):
            return
        gap = now - last
        if gap >= watchdog_s - self.period_s:
            with self._gate():
                arm_watchdog(self.bus, self.config)
            if motion.move is not Move.PARK:
                raise TickGap(gap, watchdog_s)

    def _read_if_due(self, now: float, motion: Motion) -> None:
        self._since_read += 1
        rb = self.readback
        if not (rb.retrying or self._since_read >= self.config.bus.read_divider):
            return
        self._since_read = 0
        self.read_this_tick = True
        try:
            rb.read(self.bus, self.disabled, now, self.counters)
        except (HardwareFault, TickGap):
            raise
        except DeviceError:
            if not motion.faulted:
                raise
            self.counters["read_failures_while_parking"] += 1  # the park goes on regardless
        finally:
            self.tracking = rb.tracking_error(self.goals)
        self._last_read = now

    def _parked(self, goals: Sequence[float], now: float) -> bool:
        """The park goals are out and every servo has arrived (as read after that), or
        the park's budget ``park_s`` is used up (a servo that cannot be read, or cannot
        get there): the wait for arrival comes out of ``park_s``, never adds to it. A
        ramp held back by the slew limit has less to wait; the lifecycle's
        ``park_timeout_s`` (park_s + 2 ticks from the park's start) bounds it anyway."""
        if any(abs(g - p) > 1e-6 for g, p in zip(goals, self.map.park, strict=True)):
            return False
        if self._park_goals_at is None:
            self._park_goals_at = now
        if now - self._park_goals_at >= self.config.bus.park_settle_budget_s:
            self.counters["park_not_arrived"] += 1  # torque off where they are: counted, shown
            return True
        if self._last_read is None or self._last_read <= self._park_goals_at:
            return False
        tolerance = self.config.bus.park_tolerance_deg
        return all(
            sid in self.disabled or (present is not None and abs(present - park) <= tolerance)
            for sid, present, park in zip(self.map.ids, self.readback.present_deg, self.map.park, strict=True)
        )


def rig_device(
    config: RigConfig, port: str | None = None, latch: StopLatch | None = None, period_s: float | None = None
) -> Device:
    """The Device for a rig map: ``period_s`` is how often it is ticked (the rig's own
    ``tick_hz`` when None)."""
    plug = RigPlug(config, port, period_s)
    return Device(plug, plug.period_s, latch)


def describe(file: str, port: str | None) -> DeviceInfo:
    """The registry's hook: validate a rig map (ConfigError names file and key)."""
    rig = load_rig(file)
    if port:
        rig = rig.with_port(port)
    return DeviceInfo(rig.name, rig.bus.tick_hz, wire_budget(rig), longest_wait_s=longest_tick_wait_s(rig))


def make_plug(spec: DeviceSpec) -> RigPlug:
    """The registry's hook: the plug for a planned device."""
    return RigPlug(load_rig(spec.file), spec.port, spec.period_s)
