"""One device's lifecycle, run from the tick: arming, e-stop, faults, parking, counters.

:class:`Device` wraps a :class:`~riderlive.devices.plug.Plug` and owns its
:class:`~riderlive.devices.lifecycle.Lifecycle`. The ticking thread calls :meth:`tick`
once per tick, and operator requests (:meth:`arm`, :meth:`disarm`, :meth:`reset`,
:meth:`reconnect`, :meth:`close`) between ticks; e-stops come through the shared
:class:`~riderlive.devices.latch.StopLatch` and are acted on at the next check (a tick's
start, before every goal write, while waiting for a reply, or at a wake: :meth:`poll_stop`).

Safety rules, whatever the device:

- Connecting ends in ``disarmed`` (outputs off, read back); nothing moves until an
  operator's :meth:`arm` names this device. Reset, reconnect, reload and a tick restart
  end in ``disarmed`` too, or in ``estop`` while the latch is set.
- E-stop (stop category 0): outputs off at once (one broadcast), then read back every
  tick and repeated until every unit reports off; ``estop`` until :meth:`reset`.
- A fault while armed (category 1): first aid for the unit, ease to park over the
  plug's park time, outputs off, ``fault`` (latched) with what happened. A lost
  transport cannot park: ``fault`` at once. While disarmed: outputs off, ``fault``.
- :meth:`tick` never raises.
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from collections.abc import Sequence
from typing import Any

from riderlive.devices.latch import StopLatch, StopSource, StopView
from riderlive.devices.lifecycle import (
    DeviceState,
    Fault,
    FaultKind,
    Lifecycle,
    PortLost,
    Refusal,
    Refused,
    StopRequested,
    arm_refusal,
)
from riderlive.devices.off_readback import Found, OffReadback
from riderlive.devices.plug import Motion, Move, Plug
from riderlive.devices.setup_run import Handback, HandbackTimeout, SetupRun
from riderlive.devices.status import DeviceStatus, StopRecord
from riderlive.tickframe import TickFrame

log = logging.getLogger("riderlive.devices")
S = DeviceState

_MOVES = {S.HOMING: Move.HOME, S.SOFT_START: Move.SOFT_START, S.RUNNING: Move.RUN, S.PARKING: Move.PARK}
_NEXT = {S.HOMING: S.SOFT_START, S.SOFT_START: S.RUNNING}


class Device:
    """The lifecycle of one plugged device. See the module docstring for the rules."""

    def __init__(self, plug: Plug, period_s: float, latch: StopLatch | None = None) -> None:
        self.plug = plug
        self.name = plug.name
        self.period_s = period_s
        self._own_latch = latch is None
        self.latch = StopLatch() if latch is None else latch
        self.stops: StopView = self.latch.view()
        plug.stops = self.stops
        self.life = Lifecycle(name=plug.name)
        self.counters: Counter[str] = Counter()
        self.detail = ""
        self.fault: Fault | None = None
        self.armed_by: str | None = None
        self.last_stop: StopRecord | None = None
        self._setup: SetupRun | None = None
        self.handback: Handback | None = None  # after a failover: every connect waits (``setup_run.py``)
        self._move_t0: float | None = None
        self._last_now: float | None = None
        self.readback = OffReadback(plug, period_s)
        self._configured = False
        """The last setup ran to its end (a reset from an e-stop need not repeat it)."""

    # -- what the service asks ----------------------------------------------------------

    @property
    def state(self) -> DeviceState:
        return self.life.state

    def connect(self, by: str = "service") -> None:
        """disconnected -> connecting; the setup runs over the next ticks, ends disarmed."""
        if self.state is not S.DISCONNECTED:
            raise Refused(Refusal.NOT_READY, f"{self.name} is {self.state.value}, not disconnected")
        self._begin_setup("connect", by)

    def arm(self, name: str, by: str) -> DeviceState:
        """An operator's arm, naming this device: outputs on at the present pose, then the
        soft start (or homing first). Raises Refused (nothing changes) when not allowed."""
        refused = arm_refusal(self.name, name, self.state, self.latch.latched, self.fault_message())
        if refused is not None:
            raise refused
        now = time.perf_counter()
        try:
            with self.stops.gate():  # no torque-on after an e-stop request either
                self.plug.arm()
        except StopRequested:
            self._stop(now)
            raise Refused(Refusal.ESTOPPED, f"{self.name}: e-stop during arming") from None
        except Exception as exc:
            self._on_error(exc, now)
            return self.state
        self.counters["arms"] += 1
        self.armed_by = by
        self.readback.confirmed = False
        self._start_move(S.HOMING if self.plug.needs_homing else S.SOFT_START, "armed", by, now)
        return self.state

    def disarm(self, by: str) -> DeviceState:
        """A controlled stop: ease to park, outputs off, ``parked``. Safe in any state (a
        no-op where nothing moves: a setup under way goes on and ends disarmed, outputs off,
        so a stop that meets a restarting tick never leaves a device disconnected for good)."""
        if self.state.armed:
            self.counters["disarms"] += 1
            self._start_move(S.PARKING, "disarmed", by, time.perf_counter())
        return self.state

    def reset(self, by: str) -> DeviceState:
        """Clear an e-stop or a fault: to ``disarmed`` (``connecting`` first when the
        transport must be reopened or the units checked again). Never arms."""
        state = self.state
        if state is S.PARKING:
            raise Refused(Refusal.PARKING, f"{self.name} is parking; reset clears an e-stop or a fault")
        if state not in (S.ESTOP, S.FAULT) and not self.latch.latched:
            raise Refused(Refusal.NOTHING_TO_RESET, f"{self.name} is {state.value}: nothing to reset")
        self.latch.clear()
        self.counters["resets"] += 1
        if state is S.ESTOP and self.fault is None and self.plug.is_open and self._configured:
            self._go(S.DISARMED, "reset", by)
        elif state in (S.ESTOP, S.FAULT):
            if self.fault is not None and self.fault.kind is FaultKind.PORT_LOST:
                self.plug.close()
            self._begin_setup("reset", by)
        return self.state

    def reconnect(self, by: str) -> DeviceState:
        """Close and reopen the transport, check and configure: ends disarmed (or estop)."""
        if self.state.moving:
            raise Refused(Refusal.MOVING, f"{self.name} is {self.state.value}: disarm it first")
        self._quiet_off()
        self.plug.close()
        self._begin_setup("reconnect", by)
        return self.state

    def estop(self, source: StopSource = StopSource.API) -> None:
        """Request an e-stop and act on it now (from the ticking thread; other threads and
        processes request through the latch and the next check acts)."""
        self.latch.request(source)
        self.poll_stop(time.perf_counter())

    def poll_stop(self, now: float) -> bool:
        """Act on a pending e-stop request now; True if there was one."""
        if not self.stops.pending:
            return False
        self._stop(now)
        return True

    def takeover(self, pose: Sequence[float], moving: bool, by: str = "guardian") -> None:
        """The guardian's entry: the process that drove this device died. Open the
        transport; ease from ``pose`` to park if it was moving (category 1 stop), else
        make sure its outputs are off."""
        now = time.perf_counter()
        self.plug.takeover(pose)
        if moving and not self.latch.latched:
            self.counters["takeovers"] += 1
            self._start_move(S.PARKING, "takeover: the controller died, category 1 stop", by, now)
            return
        self._go(S.CONNECTING, "takeover", by, now)
        self._outputs_off(now)
        latched = self.latch.latched
        self._go(S.ESTOP if latched else S.DISARMED, "takeover: outputs off", "latch" if latched else by, now)

    def close(self, by: str = "service", timeout_s: float | None = None) -> None:
        """Park if moving (bounded), outputs off, close the transport: ``disconnected``."""
        if self.state.armed:
            self.disarm(by)
        limit = time.perf_counter() + (self.plug.park_timeout_s if timeout_s is None else timeout_s)
        next_tick = time.perf_counter()
        while self.state is S.PARKING and time.perf_counter() < limit:
            self.tick(None, time.perf_counter())  # parking needs no frame
            next_tick += self.period_s
            time.sleep(max(0.0, next_tick - time.perf_counter()))
        self._setup = None
        self._quiet_off()
        self.plug.close()
        if self.state is not S.DISCONNECTED:
            self._go(S.DISCONNECTED, "closed", by)
        if self._own_latch:
            self.latch.close()

    def fault_message(self) -> str:
        return "none" if self.fault is None else self.fault.message

    # -- the tick -----------------------------------------------------------------------

    def tick(self, frame: TickFrame | None, now: float) -> DeviceStatus:
        """One tick: ``frame`` is the tick's frame the plug maps to goals (None outside a
        tick: parking needs none), ``now`` perf_counter seconds. Never raises."""
        self.counters["ticks"] += 1
        wrote = False
        try:
            self.poll_stop(now)
            state = self.state
            if state is S.CONNECTING:
                self._run_setup(now)
            elif state.moving:
                wrote = self._move(frame, now)
            elif state is not S.DISCONNECTED:
                if self.plug.is_open:
                    self.plug.idle(now)
                self._keep_off(now)
        except StopRequested:
            self._stop(now)
        except Exception as exc:  # nothing escapes: the tick must go on
            if self.stops.pending:
                self._stop(now)
            else:
                self._on_error(exc, now)
        self._last_now = now
        return self.status(now, wrote)

    def status(self, now: float, wrote: bool = False, *, drain: bool = True) -> DeviceStatus:
        """The device at ``now``; ``drain``: take the lifecycle's transitions since the last
        (the tick's status does; a look between ticks, after a request, leaves them)."""
        return DeviceStatus(
            name=self.name,
            kind=self.plug.kind,
            state=self.state,
            detail=self.detail,
            at=now,
            fault=self.fault,
            armed_by=self.armed_by if self.state.armed else None,
            outputs_off_confirmed=self.readback.confirmed and not self.state.moving,
            estop=self.last_stop,
            wrote=wrote,
            transitions=self.life.drain() if drain else (),
            counters={**self.counters, **self.plug.counters},
            extra=self.plug.status(),
        )

    # -- steps --------------------------------------------------------------------------

    def _go(self, target: DeviceState, reason: str, by: str, now: float | None = None) -> None:
        self.life.go(target, time.perf_counter() if now is None else now, reason, by)
        self.counters["transitions"] += 1

    def _begin_setup(self, reason: str, by: str) -> None:
        self.fault = None
        self._configured = False
        self._setup = SetupRun(self.plug, self._say, self.counters, self.handback)  # a reset waits too
        self._go(S.CONNECTING, reason, by)

    @property
    def waiting_for_handback(self) -> bool:  # connecting, transport untouched: the guardian holds the last one's
        return self._setup is not None and self._setup.waiting

    def _say(self, detail: str) -> None:
        self.detail = detail

    def _run_setup(self, now: float) -> None:
        """The setup's transactions for half a tick (the rest is the tick's): ends disarmed
        (or ``estop`` while latched); a setup past ``SETUP_TIMEOUT_S`` raises (a fault)."""
        if self._setup is None or not self._setup.advance(0.5 * self.period_s):
            return
        self._setup = None
        self._configured = True
        self.detail = ""
        self.readback.restart(now, now)
        if self.latch.latched:
            self._go(S.ESTOP, "connected while the e-stop is latched", "latch", now)
        else:
            self._go(S.DISARMED, "connected, checked, configured, outputs off", "setup", now)

    def _start_move(self, target: DeviceState, reason: str, by: str, now: float) -> None:
        self._move_t0 = None
        self._go(target, reason, by, now)

    def _move(self, frame: TickFrame | None, now: float) -> bool:
        state = self.state
        first = self._move_t0 is None
        if self._move_t0 is None:
            self._move_t0 = now
        dt = 0.0 if self._last_now is None else min(max(now - self._last_now, 0.0), 4.0 * self.period_s)
        motion = Motion(_MOVES[state], now - self._move_t0, dt, first, faulted=self.fault is not None)
        done = self.plug.drive(frame, now, motion)
        if state is S.PARKING and not done and now - self._move_t0 >= self.plug.park_timeout_s:
            self.counters["park_timeouts"] += 1
            done = True
        if done and state in _NEXT:
            self._start_move(_NEXT[state], f"{motion.move.value} done", "device", now)
        elif done and state is S.PARKING:
            self._outputs_off(now)
            if self.fault is not None:
                self._go(S.FAULT, f"parked after: {self.fault.message}", "device", now)
            else:
                self._go(S.PARKED, "parked, outputs off", "device", now)
        return True

    def _outputs_off(self, now: float) -> None:
        self.plug.outputs_off()
        self.readback.written(now)

    def _keep_off(self, now: float) -> None:
        """Outputs must be off: read back (``off_readback.py``); repeat the outputs-off until
        every unit reports it."""
        found = self.readback.check(now)
        stop = self.last_stop if self.state is S.ESTOP else None
        if found is Found.CONFIRMED:
            if stop is not None and stop.confirmed_at is None:
                stop.confirmed_at = now
            log.debug("%s: outputs off, read back", self.name)
        elif found is Found.NOT_OFF:
            self.counters["off_repeats"] += 1
            if stop is not None:
                stop.repeats += 1
            self.plug.outputs_off()

    def _stop(self, now: float) -> None:
        """Act on the e-stop request(s): outputs off at once, ``estop``, read back after."""
        self.stops.take()
        self._setup = None
        self.counters["estops"] += 1
        source = self.latch.source
        record = StopRecord(source.label if source else "api", self.latch.requested_at, time.perf_counter())
        begun = getattr(self.plug, "goal_begun_at", None)  # a plug that says when its goal writes begin
        record.last_goal_at = begun if isinstance(begun, float) else None
        self.last_stop = record
        self.readback.restart(now, now)
        try:
            if self.plug.is_open:
                self.plug.outputs_off()
                first = self.plug.off_written_at  # a plug that writes twice: the first
                record.off_written_at = first if first is not None else time.perf_counter()
                self.readback.written(now)
        except Exception as exc:
            log.error("%s: e-stop: outputs-off failed: %s", self.name, exc)
            self.counters["estop_write_failures"] += 1
            if isinstance(exc, PortLost):
                self.plug.close()
        if self.state is not S.ESTOP:
            self._go(S.ESTOP, "e-stop", record.source, now)

    def _on_error(self, error: BaseException, now: float) -> None:
        """A failure becomes a fault and the safe state for it (never raises)."""
        try:
            fault = Fault.from_error(error, now)
            self.counters["faults"] += 1
            self.counters[f"fault_{fault.kind.value}"] += 1
            state = self.state
            self._setup = None
            log.error(
                "%s: fault in %s: %s", self.name, state.value, fault.message, exc_info=fault.kind is FaultKind.INTERNAL
            )
            if isinstance(error, PortLost):
                self.fault = fault
                self.plug.close()
                self.readback.confirmed = False
                if state is not S.ESTOP:
                    self._go(S.FAULT, fault.message, "device", now)
                return
            if isinstance(error, HandbackTimeout):
                self.handback = None  # given up: a reset connects at once
            self._quietly(lambda: self.plug.on_fault(error))
            if state.armed:
                self.fault = fault
                self._start_move(S.PARKING, f"fault: {fault.message}", "device", now)
                return
            if state is S.PARKING:
                self.fault = self.fault or fault  # keep parking; the first fault is the one reported
                return
            self._quiet_off()
            if state is S.ESTOP:
                return  # already off and latched; the read-back goes on
            self.fault = fault
            self._go(S.FAULT, fault.message, "device", now)
        except Exception:
            log.exception("%s: handling a fault failed; forcing fault", self.name)
            self.life.state = S.FAULT

    def _quietly(self, call: Any) -> None:
        try:
            call()
        except Exception as exc:
            log.warning("%s: best-effort call failed: %s", self.name, exc)

    def _quiet_off(self) -> None:
        if self.plug.is_open:
            self._quietly(self.plug.outputs_off)
        self.readback.confirmed = False
