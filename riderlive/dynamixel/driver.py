"""The rig driver: rider frames in, one goal write per tick out, failing safe.

:class:`RigDriver` runs the lifecycle of :mod:`riderlive.dynamixel.lifecycle` from the
service's tick. Every step is non-blocking: connecting, checking and configuring are
a generator of single bus transactions, run a few per tick within a share of the
tick; running is one SYNC_WRITE of goal positions per tick plus, every
``read_divider`` ticks, one (Fast) Sync Read of present position, input voltage,
temperature and the status ERR byte (whose Alert bit says "read Hardware Error
Status"). That steady write stream also feeds the servos' Bus Watchdog, so they stop
by themselves when the service dies or the cable is pulled.

``tick()`` never raises: a failure becomes a :class:`Fault` and a state (park, then
torque off; or straight to torque off when the bus is gone). ``estop()`` may be
called from any thread: it gives up a reply the tick is waiting for, then sends the
torque-off broadcast. The start-up sequence is :mod:`riderlive.dynamixel.bringup`, the
divided read :mod:`riderlive.dynamixel.readback`, the bus :mod:`riderlive.dynamixel.sdkbus`.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Sequence

from riderlive.channels import RIDER
from riderlive.dynamixel.bringup import Steps, arm_watchdog, bring_up
from riderlive.dynamixel.lifecycle import (
    Fault,
    FaultKind,
    Lifecycle,
    PortLost,
    RigError,
    RigState,
    ServoHardwareError,
    TickGap,
    Transition,
)
from riderlive.dynamixel.readback import Readback
from riderlive.dynamixel.rig import (
    RigConfig,
    ServoMap,
    deg_to_pulses,
    smoothstep,
)
from riderlive.dynamixel.sdkbus import SdkBus
from riderlive.dynamixel.status import BusCounters, RigStatus
from riderlive.dynamixel.tables import Item

log = logging.getLogger("riderlive.dynamixel")

_SETUP = frozenset({RigState.CONNECTING, RigState.CHECKING, RigState.CONFIGURING})


class RigDriver:
    """Drives one rig from the tick. See the module docstring for the contract."""

    def __init__(self, config: RigConfig, port: str | None = None) -> None:
        self.config = config if port is None else config.with_port(port)
        bus = self.config.bus
        self.map = ServoMap(self.config)
        self._servos = list(self.config.servos.values())
        self._readback = Readback(self.config)
        self._bus = SdkBus(bus.port, bus.baud, bus.latency_timer_ms, bus.timeout_margin_ms)
        self._life = Lifecycle()
        self._lock = threading.Lock()
        self._estop_requested = False
        self._estop_repeat = False
        self._setup: Steps[None] | None = None
        self._fault: Fault | None = None
        self.counters = BusCounters()
        n = len(self.map)
        self._goals: list[float] = list(self.map.park)
        self._clamped: list[bool] = [False] * n
        self._tracking: list[float | None] = [None] * n
        self._hw: dict[int, tuple[str, ...]] = {}
        self._disabled: set[int] = set()
        self._ramp_from: list[float] = list(self._goals)
        self._ramp_t0: float | None = None
        self._park_goals_at: float | None = None
        self._last_read: float | None = None
        self._last_now: float | None = None
        self._armed = False
        """The Bus Watchdog is armed (set at the end of configuring)."""
        self._since_read = 0

    # --- the interface the service calls -------------------------------------------

    @property
    def state(self) -> RigState:
        return self._life.state

    @property
    def fault(self) -> Fault | None:
        return self._fault

    @property
    def history(self) -> tuple[Transition, ...]:
        """The last 256 transitions (each status carries only those since the previous tick)."""
        return tuple(self._life.history)

    @property
    def last_packet_at(self) -> float | None:
        """perf_counter when the last instruction packet was written (it fed the Bus Watchdog)."""
        return self._bus.port.last_write

    def open(self) -> bool:
        """Start the lifecycle (connect, check, configure, soft start) over the next ticks."""
        with self._lock:
            if self.state is not RigState.CLOSED:
                log.warning("open() ignored in state %s", self.state.value)
                return False
            self._begin(connect=True, reason="open()")
            return True

    def tick(self, rider: Sequence[float], now: float) -> RigStatus:
        """One tick: ``rider`` in ``channels.RIDER`` order, ``now`` in perf_counter seconds."""
        with self._lock:
            first_tx = self._bus.transactions
            wrote = read = False
            self.counters.ticks += 1
            try:
                if self._estop_requested:
                    self._do_estop(now, "estop()")
                if self._estop_repeat and self._bus.is_open:
                    self._estop_repeat = False
                    self._torque_off_all()
                if self.state in _SETUP:
                    self._run_setup()
                elif self.state.torque_may_be_on:
                    wrote, read = self._drive(rider, now)
            except Exception as exc:  # nothing escapes tick(): the service must keep running
                self._on_error(exc, now)
            self._last_now = now
            return self._status(now, wrote, read, self._bus.transactions - first_tx)

    def estop(self) -> None:
        """Torque off every servo now. Callable from any thread: a reply the tick is
        waiting for is given up, then the torque-off broadcast goes out (and once more
        on the next tick, in case it met that reply on the half-duplex wire)."""
        self._estop_requested = True
        self._bus.port.abort_wait = True
        if self._lock.acquire(timeout=self.config.bus.tick_s):
            try:
                if self._estop_requested:
                    self._do_estop(time.perf_counter(), "estop()")
            except Exception:
                log.exception("e-stop: torque-off write failed")
            finally:
                self._lock.release()

    def request_park(self) -> None:
        """Ease to the park pose, then torque off (state TORQUE_OFF)."""
        with self._lock:
            now = time.perf_counter()
            try:
                if self.state in (RigState.SOFT_START, RigState.RUNNING):
                    self._start_park(now, "request_park()")
                elif self.state in (RigState.CHECKING, RigState.CONFIGURING):
                    self._setup = None
                    self._torque_off_all()
                    self._go(RigState.TORQUE_OFF, "request_park() during setup", now)
                elif self.state is RigState.CONNECTING:
                    self._setup = None
                    self._bus.close()
                    self._go(RigState.CLOSED, "request_park() while connecting", now)
            except Exception as exc:
                self._on_error(exc, now)

    def reset(self) -> bool:
        """Leave FAULT / ESTOP / TORQUE_OFF: check and configure again, then soft start."""
        with self._lock:
            if self.state not in (RigState.FAULT, RigState.ESTOP, RigState.TORQUE_OFF):
                log.warning("reset() ignored in state %s", self.state.value)
                return False
            self._begin(connect=not self._bus.is_open, reason="reset()")
            return True

    def reconnect(self) -> bool:
        """Close and reopen the port (after it vanished), then start as reset() does."""
        with self._lock:
            if self.state not in (RigState.FAULT, RigState.ESTOP, RigState.TORQUE_OFF, RigState.CLOSED):
                log.warning("reconnect() ignored in state %s", self.state.value)
                return False
            self._bus.close()
            self._begin(connect=True, reason="reconnect()")
            return True

    def close(self) -> None:
        """Park (bounded by ``park_s + close_timeout_s``), torque off, close the port."""
        bus = self.config.bus
        self.request_park()
        deadline = time.perf_counter() + bus.park_s + bus.close_timeout_s
        hold = [0.0] * len(RIDER)
        next_tick = time.perf_counter()
        while self.state is RigState.PARKING and time.perf_counter() < deadline:
            self.tick(hold, time.perf_counter())
            next_tick += bus.tick_s
            time.sleep(max(0.0, next_tick - time.perf_counter()))
        with self._lock:
            self._setup = None
            try:
                if self._bus.is_open:
                    self._torque_off_all()
            except Exception:
                log.exception("close(): torque-off write failed")
            self._bus.close()
            if self.state is not RigState.CLOSED:
                self._go(RigState.CLOSED, "close()", time.perf_counter())

    # --- lifecycle steps -------------------------------------------------------------

    def _go(self, target: RigState, reason: str, now: float | None = None) -> None:
        self._life.go(target, time.perf_counter() if now is None else now, reason)

    def _begin(self, connect: bool, reason: str) -> None:
        self._fault = None
        self._hw.clear()
        self._disabled.clear()
        self._readback.restart()
        self._armed = False
        self._go(RigState.CONNECTING if connect else RigState.CHECKING, reason)
        self._setup = self._startup(connect)

    def _run_setup(self) -> None:
        """Run setup transactions until this tick's share of time is used."""
        budget_end = time.perf_counter() + self.config.bus.setup_share * self.config.bus.tick_s
        while self._setup is not None:
            try:
                next(self._setup)
            except StopIteration:
                self._setup = None
            if time.perf_counter() >= budget_end:
                break

    def _startup(self, connect: bool) -> Steps[None]:
        present = yield from bring_up(self._bus, self.config, connect, self._go)
        self._readback.present_deg[:] = present
        self._goals = self.map.within_limits(present)  # what configuring wrote as goals
        self._armed = bool(self.config.bus.bus_watchdog_ms)
        self._ramp_t0 = None
        self._readback.restart()
        self._go(RigState.SOFT_START, "configured, torque on")

    # --- running ---------------------------------------------------------------------

    def _drive(self, rider: Sequence[float], now: float) -> tuple[bool, bool]:
        """One goal SYNC_WRITE, then the divided read. Returns (wrote, read)."""
        bus = self.config.bus
        state = self.state
        dt = 0.0 if self._last_now is None else min(max(now - self._last_now, 0.0), 4.0 * bus.tick_s)
        watchdog_s = bus.bus_watchdog_ms / 1000.0
        last_packet = self._bus.port.last_write if self._armed else None
        if watchdog_s and last_packet is not None and now - last_packet >= watchdog_s - bus.tick_s:
            gap = now - last_packet
            arm_watchdog(self._bus, self.config)  # the goals are read-only while it is tripped
            if state is not RigState.PARKING:
                raise TickGap(gap, watchdog_s)
        if self._ramp_t0 is None:
            self._ramp_t0, self._ramp_from = now, list(self._goals)
        elapsed = now - self._ramp_t0
        if state is RigState.PARKING:
            alpha = smoothstep(elapsed / bus.park_s) if bus.park_s > 0 else 1.0
            targets = [f + alpha * (p - f) for f, p in zip(self._ramp_from, self.map.park, strict=True)]
        else:
            if len(rider) != len(RIDER) or not all(map(math.isfinite, rider)):
                self.counters.bad_inputs += 1
                if len(rider) != len(RIDER):
                    rider = [math.nan] * len(RIDER)
            targets = self.map.targets(rider, self._goals)
            alpha = 1.0
            if state is RigState.SOFT_START:
                alpha = smoothstep(elapsed / bus.soft_start_s) if bus.soft_start_s > 0 else 1.0
                targets = [f + alpha * (t - f) for f, t in zip(self._ramp_from, targets, strict=True)]
        goals, clamped = self.map.limit(targets, self._goals, dt)
        goal_spec = self._servos[0].spec.spec(Item.GOAL_POSITION)
        pulses = {sid: deg_to_pulses(g) for sid, g in zip(self.map.ids, goals, strict=True)}
        for sid in self._disabled:
            del pulses[sid]
        self._bus.sync_write(goal_spec, pulses)
        self._goals, self._clamped = goals, clamped
        self.counters.goal_writes += 1
        self.counters.clamps += sum(clamped)
        if self._estop_requested:
            self._do_estop(now, "estop()")
            return True, False
        if state is RigState.PARKING and alpha >= 1.0 and self._parked(goals, now):
            self._torque_off_all()
            target = RigState.FAULT if self._fault is not None else RigState.TORQUE_OFF
            self._go(target, "parked, torque off", now)
            return True, False
        if state is RigState.SOFT_START and alpha >= 1.0:
            self._go(RigState.RUNNING, "soft start done", now)
        self._since_read += 1
        reads_ok = self._fault is None or self._fault.kind in (FaultKind.HARDWARE_ERROR, FaultKind.TICK_GAP)
        if reads_ok and (self._readback.retrying or self._since_read >= bus.read_divider):
            self._since_read = 0
            try:
                self._readback.read(self._bus, self._disabled, now, self.counters)
            finally:
                self._tracking = self._readback.tracking_error(self._goals)
            self._last_read = now
            return True, True
        return True, False

    def _parked(self, goals: Sequence[float], now: float) -> bool:
        """The park goals are out and every servo has arrived (as read after that), or
        ``park_settle_s`` has passed (a servo that cannot be read, or cannot get there)."""
        if any(abs(g - p) > 1e-6 for g, p in zip(goals, self.map.park, strict=True)):
            return False
        if self._park_goals_at is None:
            self._park_goals_at = now
        if now - self._park_goals_at >= self.config.bus.park_settle_s:
            return True
        if self._last_read is None or self._last_read <= self._park_goals_at:
            return False
        tolerance = self.config.bus.park_tolerance_deg
        return all(
            sid in self._disabled or (present is not None and abs(present - park) <= tolerance)
            for sid, present, park in zip(self.map.ids, self._readback.present_deg, self.map.park, strict=True)
        )

    def _start_park(self, now: float, reason: str) -> None:
        self._ramp_t0, self._ramp_from = now, list(self._goals)
        self._park_goals_at = None
        self._go(RigState.PARKING, reason, now)

    def _torque_off_all(self) -> None:
        """Torque Enable = 0 written to the broadcast ID: 13 bytes, every servo on the bus
        (mapped or not) obeys, no reply to wait for."""
        self._bus.broadcast_write(self._servos[0].spec.spec(Item.TORQUE_ENABLE), 0)

    def _do_estop(self, now: float, reason: str) -> None:
        self._estop_requested = False
        self._bus.port.abort_wait = False
        self._setup = None
        self.counters.estops += 1
        try:
            if self._bus.is_open:
                self._torque_off_all()
                self._estop_repeat = True
        finally:
            self._go(RigState.ESTOP, reason, now)

    def _on_error(self, error: BaseException, now: float) -> None:
        """Turn a failure into a fault and the safe state for it (never raises)."""
        try:
            fault = Fault.from_error(error, now)
            self._fault = fault
            self.counters.faults += 1
            self._setup = None
            log.error("rig fault in %s: %s", self.state.value, fault.message, exc_info=fault.kind.value == "internal")
            state = self.state
            if isinstance(error, PortLost):
                self._quiet_torque_off()
                self._bus.close()
            elif isinstance(error, ServoHardwareError):
                self._hw[error.servo_id] = error.bits
                self._disabled.add(error.servo_id)
                torque = self._servos[0].spec.spec(Item.TORQUE_ENABLE)
                self._quietly(lambda: self._bus.write(error.servo_id, torque, 0))
            if state in (RigState.SOFT_START, RigState.RUNNING) and not isinstance(error, PortLost):
                self._start_park(now, f"fault: {fault.message}")
                return
            if state is not RigState.ESTOP:
                if not isinstance(error, PortLost):
                    self._quiet_torque_off()
                self._go(RigState.FAULT, fault.message, now)
        except Exception:
            log.exception("rig: handling a fault failed; forcing FAULT")
            self._life.state = RigState.FAULT

    def _quietly(self, call: Callable[[], None]) -> None:
        try:
            call()
        except (RigError, OSError) as exc:
            log.warning("rig: best-effort write failed: %s", exc)

    def _quiet_torque_off(self) -> None:
        if self._bus.is_open:
            self._quietly(self._torque_off_all)

    def _status(self, now: float, wrote: bool, read: bool, transactions: int) -> RigStatus:
        return RigStatus(
            state=self.state,
            at=now,
            tick=self.counters.ticks,
            names=self.map.names,
            ids=self.map.ids,
            goal_deg=tuple(self._goals),
            clamped=tuple(self._clamped),
            present_deg=tuple(self._readback.present_deg),
            tracking_error_deg=tuple(self._tracking),
            temperature_c=tuple(self._readback.temperature_c),
            voltage_v=tuple(self._readback.voltage_v),
            hardware_errors=dict(self._hw),
            fault=self._fault,
            wrote=wrote,
            read=read,
            fast_sync_read=self._readback.use_fast,
            transactions=transactions,
            transitions=tuple(self._life.drain()),
            counters=self.counters.to_dict(),
        )
