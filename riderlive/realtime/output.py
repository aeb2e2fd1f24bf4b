"""The devices the tick drives: built from their specs, ticked, commanded, reported.

:class:`TickDevices` holds one :class:`~riderlive.devices.device.Device` per
configured device (the Dynamixel rig today, the motion platform next). Each is ticked
every ``spec.divider``-th tick (a device validated for a lower rate than the service's),
publishes its state and last goal pose to the safety board for the guardian, and
answers the operators' requests (arm, disarm, reset, reload) with a
:class:`~riderlive.realtime.commands.Reply`. E-stops come through the shared latch:
:meth:`act_on_stop` applies a new request to every device at once, whatever their
dividers.
"""

from __future__ import annotations

import functools
import logging
import time
from collections.abc import Sequence
from typing import Any

from riderlive.devices.board import SafetyBoard, guardian_watching
from riderlive.devices.device import Device
from riderlive.devices.guardians import handback_pending
from riderlive.devices.iowait import BoardIoWait, DeclaresIoWaits
from riderlive.devices.latch import StopLatch
from riderlive.devices.lifecycle import DeviceState, Refusal, Refused
from riderlive.devices.plug import NotTunable
from riderlive.devices.registry import DeviceSpec, make_plug
from riderlive.devices.setup_run import Handback
from riderlive.devices.status import DeviceStatus
from riderlive.realtime import commands as cmd
from riderlive.tickframe import TickFrame

log = logging.getLogger(__name__)
REST_STATES = frozenset({DeviceState.DISCONNECTED, DeviceState.DISARMED, DeviceState.PARKED})
REST_STATES |= {DeviceState.ESTOP, DeviceState.FAULT}
"""States in which a device holds no pose: shutdown may stop ticking."""
GUARDIAN_CHECK_S = 0.005
"""How often the tick looks at the guardian (its pid and heartbeat on the safety board)."""


class TickDevices:
    """The tick's devices; every method runs in the tick's thread."""

    def __init__(
        self,
        specs: Sequence[DeviceSpec],
        latch: StopLatch,
        board: SafetyBoard | None = None,
        guardian_required: bool = False,
        arm_on_start: str | None = None,
    ) -> None:
        self.specs = list(specs)
        self.latch = latch
        self.board = board
        self.guardian_required = guardian_required
        self.arm_on_start = arm_on_start
        """Who asked (``serve --arm``): arm each device once, when it first gets to disarmed."""
        self.devices = [Device(make_plug(spec), spec.period_s, latch) for spec in self.specs]
        self.stops = latch.view()
        if board is not None:  # each reply wait declared on the board: not a hang (``devices/iowait.py``)
            for device in self.devices:
                if isinstance(device.plug, DeclaresIoWaits):
                    device.plug.io_wait = BoardIoWait(board)
        self.statuses: list[DeviceStatus | None] = [None] * len(self.devices)
        self._auto_armed: set[str] = set()
        self.goal_written_at: float | None = None
        """perf_counter time this tick's last goal write returned (None: no device wrote a goal)."""
        self.guardian_lost: str | None = None
        """Why no guardian watches now (None: one does); see :meth:`watch_guardian`."""
        self.guardian_losses = 0
        """Times a watching guardian was lost (dead or hung) while this tick ran."""
        self.guardian_stops = 0
        """Armed devices this tick stopped itself because the guardian was lost."""
        self.arms_refused_no_guardian = 0
        self._guardian_next = 0.0
        self._guardian_seen = False
        self._guardian_pid = 0
        """The guardian last seen watching (a new pid means the one that watched is gone)."""

    def open(self, handback_bound_s: float = 0.0) -> None:
        """Connect every device; with a board naming a generation the guardian must hand back
        first (a failover), each waits for it up to ``handback_bound_s`` without touching its
        transport (``devices/guardians.py`` :func:`handback_pending`)."""
        for i, device in enumerate(self.devices):
            if self.board is not None and self.board.handback_from:
                device.handback = Handback(functools.partial(handback_pending, self.board, i), handback_bound_s)
            device.connect("tick")

    # -- e-stop --------------------------------------------------------------------------

    def stop_pending(self) -> bool:
        """A new e-stop request (cheap: checked while the tick spins before a deadline)."""
        return self.stops.pending

    def act_on_stop(self, now: float) -> bool:
        """A new e-stop request: every device acts on it now. True if there was one."""
        if not self.stops.take():
            return False
        for device in self.devices:
            device.poll_stop(now)
        return True

    # -- the tick ------------------------------------------------------------------------

    def tick(self, frame: TickFrame) -> bool:
        """Tick each device that is due at ``frame.tick`` with the tick's frame (each reads the
        parts it consumes) at ``frame.at``; True when a state changed (publish now)."""
        changed = self.watch_guardian(frame.at)
        self.goal_written_at = None
        now = frame.at
        for i, (spec, device) in enumerate(zip(self.specs, self.devices, strict=True)):
            if frame.tick % spec.divider:
                continue
            before, last = device.state, self.statuses[i]
            said = last.detail if last is not None else None
            status = device.tick(frame, now)
            if status.wrote:
                self.goal_written_at = device.plug.goal_written_at or time.perf_counter()
            self.statuses[i] = status
            # a new detail too (e.g. what the guardian reports while a connect waits for it)
            changed |= status.state is not before or bool(status.transitions) or status.detail != said
            if self.board is not None and not device.waiting_for_handback:  # the guardian's slot until then
                self.board.publish(i, device.state, device.plug.pose)
            if self.arm_on_start and device.state is DeviceState.DISARMED and device.name not in self._auto_armed:
                self._auto_armed.add(device.name)
                try:
                    self._arm(device, self.arm_on_start)
                except Refused as exc:
                    log.error("%s: not armed at start: %s", device.name, exc)
        return changed

    # -- requests ------------------------------------------------------------------------

    def request(self, command: cmd.Request) -> cmd.Reply:
        """Apply an operator's request; refusals come back in the reply, never raised. The
        devices' statuses are taken again at once, so :meth:`status` says what the reply says."""
        try:
            message = self._apply(command)
            reply = cmd.Reply(command.request, True, self.states(), None, message)
        except Refused as exc:
            log.warning("refused %s: %s", type(command).__name__.lower(), exc)
            reply = cmd.Reply(command.request, False, self.states(), exc.reason.value, str(exc))
        now = time.perf_counter()
        self.statuses = [device.status(now, drain=False) for device in self.devices]
        return reply

    def _apply(self, command: cmd.Request) -> str:
        if isinstance(command, cmd.Arm):
            device = self._named(command.device)
            self._arm(device, command.by)
            return f"{device.name} armed by {command.by}: {device.state.value}"
        if isinstance(command, cmd.Tune):
            return self._tune(self._named(command.device), command)
        targets = self.devices if command.device is None else [self._named(command.device)]
        if isinstance(command, cmd.Disarm):
            for device in targets:
                device.disarm(command.by)
            return "disarmed"
        if isinstance(command, cmd.Reset):
            return self._reset(targets, command)
        return self._reload(targets[0], command.by)

    def _named(self, name: str) -> Device:
        for device in self.devices:
            if device.name == name:
                return device
        known = ", ".join(repr(d.name) for d in self.devices) or "none configured"
        raise Refused(Refusal.UNKNOWN_DEVICE, f"no device {name!r} (devices: {known})")

    def _arm(self, device: Device, by: str) -> None:
        if self.guardian_required:
            why = self._guardian_why(time.perf_counter())
            if why is not None:
                self.arms_refused_no_guardian += 1
                raise Refused(Refusal.NO_GUARDIAN, f"{why}: nothing may move until a guardian watches")
            self.guardian_lost, self._guardian_seen = None, True  # seen watching: a loss from here counts
            self._guardian_pid = 0 if self.board is None else int(self.board.guardian_pid)
        device.arm(device.name, by)

    def guardian_alive(self) -> bool:
        return self.board is not None and self._guardian_why(time.perf_counter()) is None

    def _guardian_why(self, now: float) -> str | None:
        return "no safety board" if self.board is None else guardian_watching(self.board, now)

    def watch_guardian(self, now: float) -> bool:
        """The watched watchman: every ``GUARDIAN_CHECK_S``, with a guardian required, look at
        it; dead, hung or not there, each armed device gets a category 1 stop from the tick
        itself (its disarm: ease to park, outputs off, read back). True when that happened."""
        if not self.guardian_required or now < self._guardian_next:
            return False
        self._guardian_next = now + GUARDIAN_CHECK_S
        why = self._guardian_why(time.perf_counter())
        pid = 0 if self.board is None else int(self.board.guardian_pid)
        replaced_now = False
        if why is None:
            replaced_now, self._guardian_pid = self._guardian_pid not in (0, pid), pid
            if replaced_now:
                # A standby became the guardian between two looks: the one that watched is gone all
                # the same (a fault of the safety chain): the same stop; arming may follow at once.
                why, self.guardian_lost = f"the guardian that watched is gone (its standby {pid} watches now)", None
        if why is None:
            self._guardian_seen = True
            if self.guardian_lost is not None:
                log.warning("a guardian watches again (nothing re-arms)")
            self.guardian_lost = None
            return False
        if not replaced_now:
            self._guardian_pid = 0  # a loss seen as such: the next guardian is no replacement
        if self.guardian_lost is None and self._guardian_seen:
            self.guardian_losses += 1
            log.critical("%s: armed devices park (category 1 stop by the tick), arming is refused", why)
        self.guardian_lost = why
        stopped = False
        for device in self.devices:
            if device.state.armed:
                device.counters["guardian_stops"] += 1
                self.guardian_stops += 1
                device.disarm(f"tick: {why}")
                stopped = True
        return stopped

    def _reset(self, targets: list[Device], command: cmd.Reset) -> str:
        done = []
        for device in targets:
            try:
                device.reset(command.by)
                done.append(device.name)
            except Refused as exc:
                if exc.reason is not Refusal.NOTHING_TO_RESET or command.device is not None:
                    raise
        self.latch.clear()
        return f"reset: {', '.join(done) or 'nothing latched'}"

    def _tune(self, device: Device, command: cmd.Tune) -> str:
        try:
            device.plug.tune(**command.changes)
        except NotTunable as exc:
            raise Refused(Refusal.BAD_CONFIG, str(exc)) from None
        except ValueError as exc:  # pydantic's ValidationError: out of range, or against another value
            raise Refused(Refusal.BAD_CONFIG, f"{device.name}: {exc}") from None
        log.info("%s: cueing tuned by %s: %s", device.name, command.by, command.changes)
        return f"{device.name} tuned: {', '.join(f'{k}={v}' for k, v in command.changes.items())}"

    def _reload(self, device: Device, by: str) -> str:
        if device.state.moving:
            raise Refused(Refusal.MOVING, f"{device.name} is {device.state.value}: disarm it before a reload")
        index = self.devices.index(device)
        try:
            plug = make_plug(self.specs[index])
        except ValueError as exc:  # ConfigError and pydantic's: the file is wrong; keep the old one
            raise Refused(Refusal.BAD_CONFIG, str(exc)) from None
        device.close(by)
        fresh = Device(plug, self.specs[index].period_s, self.latch)
        fresh.counters = device.counters  # counters stay monotonic across a reload
        fresh.counters["reloads"] += 1
        self.devices[index] = fresh
        fresh.connect(by)
        return f"{fresh.name} reloaded: connecting, then disarmed"

    # -- shutdown and status -------------------------------------------------------------

    def park(self) -> None:
        for device in self.devices:
            device.disarm("shutdown")

    def at_rest(self) -> bool:
        return all(d.state in REST_STATES for d in self.devices)

    def close(self) -> None:
        for device in self.devices:
            try:
                device.close("shutdown", timeout_s=0.0)
            except Exception as exc:
                log.warning("%s: close failed: %s", device.name, exc)

    def states(self) -> dict[str, str]:
        return {d.name: d.state.value for d in self.devices}

    def status(self) -> dict[str, Any]:
        """``devices``: one summary each; ``rig``: the first Dynamixel device in full."""
        full = []
        for device, status in zip(self.devices, self.statuses, strict=True):
            full.append((status or device.status(time.perf_counter())).to_dict())
        summary_keys = (
            "name",
            "kind",
            "state",
            "detail",
            "fault",
            "armed_by",
            "outputs_off_confirmed",
            "estop",
            "counters",
        )
        rig = next((s for s in full if s["kind"] == "dynamixel"), None)
        platform = next((s for s in full if s["kind"] == "platform"), None)
        return {
            "devices": [{k: s[k] for k in summary_keys} for s in full],
            "rig": rig,
            "platform": platform,
            "guardian": None
            if self.board is None
            else {
                "alive": self.guardian_alive(),
                "lost": self.guardian_lost,
                "losses": self.guardian_losses,
                "stops": self.guardian_stops,
                "arms_refused": self.arms_refused_no_guardian,
            },
        }
