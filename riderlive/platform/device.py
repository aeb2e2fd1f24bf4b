"""The motion platform as a device: the plug that puts firmware_proto on a serial link into the lifecycle.

:class:`PlatformPlug` is what :class:`~riderlive.devices.device.Device` drives (see
:mod:`riderlive.devices.plug`). The pure pipeline (:mod:`riderlive.platform.mechanism.pipeline`:
cueing, IK with the workspace scale-back, the safety follower) computes one target per
actuator a tick; the checked link (:mod:`riderlive.platform.serial_link`) carries it to
the firmware, which applies its own soft, speed and acceleration limits, soft start,
park and dead-man (docs/platform-link.md). Per step of the lifecycle:

- **setup**: open the port and shake hands (a wrong link version is refused, naming both),
  check the actuator count and the device's name, let a device the HELLO found moving
  finish its park, clear a latch it kept from an earlier session (counted), then tighten
  its limits to the platform file's (CONFIG: heartbeat, soft range, speed and acceleration
  per actuator; a value the firmware's profile cannot take is a ``Mismatch`` naming the
  actuator). Ends with the device disarmed, outputs off.
- **arm**: ARM naming the device (its firmware homes first when it must: ``needs_homing``).
- **drive**: the tick frame's saddle pose (``TickFrame.saddle``: the tick computes it once,
  at the service's configured saddle point, in metres and degrees) -> cueing -> IK ->
  safety follower -> one TARGET in counts of stroke from fully retracted (0.01 mm; 0.01 deg
  for a rotary arm), then the link's ``service`` (telemetry in, heartbeat out). Soft start: eased on this side over the
  platform's ``soft_start_s`` while the firmware blends too; done when both are.
  Park: a PARK frame, then the firmware's own eased park until it reports parked.
- **faults**: a fault or e-stop the firmware latched by itself (its e-stop input, its
  dead-man, a following error, a noisy link) is a ``HardwareFault`` naming its bits; a
  device that went silent is ``NoReply``; a vanished port ``PortLost``.
- **outputs_off**: an ESTOP frame (the firmware cuts its outputs at once, category 0),
  skipped only when fresh telemetry already shows them off and no e-stop is latched (a
  completed park); the next operator arm clears the firmware's latch with a RESET first.
- **takeover** (the guardian): open the port; the HELLO itself parks a moving device.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections import Counter
from collections.abc import Callable, Sequence
from typing import Any

from riderlive.channels import SADDLE
from riderlive.devices.latch import StopView
from riderlive.devices.lifecycle import HardwareFault, Mismatch, NoReply, Rejected
from riderlive.devices.plug import Motion, Move, PlugBase, Steps
from riderlive.devices.registry import DeviceInfo, DeviceSpec
from riderlive.platform import link, plug_status
from riderlive.platform.link_vocab import Flag, LinkState, Profile, config_refusal
from riderlive.platform.mechanism import pipeline
from riderlive.platform.mechanism.config import load_platform
from riderlive.platform.mechanism.pipeline import PlatformModel, PlatformState
from riderlive.platform.plug_link import config_values, lifecycle_errors, position_units, target_counts
from riderlive.platform.plug_status import fault_names
from riderlive.platform.serial_link import Health, SerialPlatformLink
from riderlive.tickframe import Part, TickFrame

HOMING_PROFILES = frozenset({Profile.PLATFORM6, Profile.PLATFORM3})
"""Profiles whose firmware homes on its first arm (firmware_proto/src/profile.c)."""
_MOVING = frozenset({LinkState.HOMING, LinkState.SOFT_START, LinkState.RUNNING, LinkState.PARKING})
_LATCHED = frozenset({LinkState.ESTOP, LinkState.FAULT})
_AT_REST = frozenset({LinkState.DISARMED, LinkState.PARKED, LinkState.ESTOP, LinkState.FAULT})
FIRMWARE_PARK_S = 6.0
"""The longest the firmware's own park may take before outputs go off regardless: 140 mm at
25 % of 250 mm/s is 2.3 s (a platform file with a lower speed takes longer: see park_timeout_s)."""
SETUP_PARK_WAIT_S = 15.0
"""At connect, how long to wait for a device the HELLO found moving to finish its park."""
FIRST_TELEMETRY_WAIT_S = 0.5
"""At the end of the setup, how long to wait for the firmware's first telemetry (it
comes every ``telemetry_ms``, 20 ms by default); past it the setup ends anyway and the
lifecycle's read-back of outputs-off decides."""


class PlatformPlug(PlugBase):
    """One platform on one serial port; see the module docstring."""

    kind = "platform"

    def __init__(
        self,
        model: PlatformModel,
        port: str,
        *,
        device: str | None = None,
        heartbeat_ms: int = 200,
        period_s: float = 0.01,
        make_link: Callable[[str], SerialPlatformLink] = SerialPlatformLink,
    ) -> None:
        self.model = model
        self.name = model.name
        self.port = port
        self.expected_device = device
        self.heartbeat_ms = heartbeat_ms
        self.period_s = period_s
        self.link = make_link(port)
        self.stops: StopView | None = None
        self.needs_homing = False
        self.counters: Counter[str] = Counter()
        self.hello: link.HelloReply | None = None
        self.units = position_units(model)
        self.state: PlatformState = pipeline.initial(model)
        self.positions: list[float] = list(model.park_positions)
        """The last positions sent (actuator units), or where the device said it was."""
        self.aim: pipeline.Aim | None = None
        self.saddle: list[float] = [0.0] * 6
        self._ramp_from: list[float] = list(self.positions)
        self._before_arm: link.Telemetry | None = None
        self._off_sent_with: link.Telemetry | None = None
        """The telemetry present when the last ESTOP went out (a fresher one confirms it)."""
        self._we_latched = False
        """The firmware's estop is ours (we sent ESTOP): not a fault of its own."""
        self._reported_faults = 0
        self._silence_reported = False
        self._silent_since: float | None = None
        self.faults_at_connect: list[str] = []
        # compile (or load) the kernels now, where the plug is made (before the tick's first
        # deadline, or the guardian's watch), never in a tick: a compile outlasts the dead-man
        pipeline.step(model, pipeline.initial(model), [0.0] * 6, period_s)

    # -- the Plug interface -------------------------------------------------------------

    @property
    def is_open(self) -> bool:
        return self.link.health in (Health.OK, Health.SILENT)

    @property
    def pose(self) -> Sequence[float]:
        return self.positions

    @property
    def park_timeout_s(self) -> float:
        """The firmware parks at 25 % of the speed limit (docs/platform-link.md), plus its accelerations."""
        g = self.model.geometry
        far = max(p - lo for p, lo in zip(self.positions, g.lower, strict=True))
        need = max(0.0, far) / (0.25 * min(g.max_speed)) + 1.0
        return max(FIRMWARE_PARK_S, need)

    def setup(self, detail: Callable[[str], None]) -> Steps[None]:
        detail(f"opening {self.port}, hello")
        self._reset_session()
        self.link.close()  # a reset after a fault reopens: the HELLO starts a new session
        hello = self._call(self.link.open)
        self.hello = hello
        yield
        detail("checking the device")
        self._check_hello(hello)
        status = self._call(lambda: self.link.command(link.Disarm(), check=False))
        deadline = time.monotonic() + SETUP_PARK_WAIT_S
        while LinkState(status.state) in _MOVING:  # the HELLO parks a moving device: let it finish
            detail("waiting for the device to finish parking")
            yield
            if time.monotonic() > deadline:
                raise NoReply(None, f"{self.port}: the device is still {LinkState(status.state).label}")
            status = self._call(lambda: self.link.command(link.Disarm(), check=False))
        if LinkState(status.state) in _LATCHED:
            self.faults_at_connect = fault_names(status.faults)
            self.counters["latch_cleared_at_connect"] += 1
            detail("clearing the latch the device kept: " + (", ".join(self.faults_at_connect) or "e-stop"))
            self._call(lambda: self.link.command(link.Reset()))
            yield
        for key, index, value in config_values(self.model, self.units, self.heartbeat_ms):
            detail(f"configuring {key.name.lower()} {index}")
            why = config_refusal(hello.profile, key, value)  # the firmware's table, said before it refuses
            if why is not None:
                raise Mismatch(
                    index, f"{self.name}: actuator {index + 1}: {why}: the platform file asks what its profile refuses"
                )
            try:
                self._call(lambda k=key, i=index, v=value: self.link.command(link.Config(k, i, v)))  # type: ignore[misc]
            except Rejected as exc:
                raise Mismatch(
                    index,
                    f"{self.name}: the firmware refused {key.name.lower()} = {value} for "
                    f"actuator {index + 1} ({exc}): the platform file asks more than its profile allows",
                ) from None
            yield
        # DISARMED means outputs off as the firmware reports them: its first telemetry
        # (every telemetry period) confirms it. Without it the lifecycle's read-back would
        # find nothing and send the outputs-off, an ESTOP frame that latches a firmware
        # which was off all along (seen on a loaded machine: host disarmed, firmware estop).
        deadline = time.monotonic() + FIRST_TELEMETRY_WAIT_S
        while self.link.telemetry is None and time.monotonic() < deadline:
            detail("waiting for the device's first telemetry")
            yield
            self._call(self.link.service)
        self.counters["setups"] += 1

    def close(self) -> None:
        self.link.close()

    def arm(self) -> None:
        """ARM naming the device; a latch the firmware kept since an e-stop is cleared first (the
        operator's reset on this side came before this arm). Starts from where the actuators are."""
        self._call(self.link.service)
        state = self.link.state
        if state in _LATCHED:
            self._call(lambda: self.link.command(link.Reset()))
            self.counters["firmware_resets"] += 1
        name = self.expected_device or (self.hello.device if self.hello else self.name)
        with self._gate():
            status = self._call(lambda: self.link.command(link.Arm(name)))
        self.needs_homing = LinkState(status.state) is LinkState.HOMING
        self._we_latched, self._reported_faults, self._silence_reported = False, 0, False
        self._before_arm = self.link.telemetry  # says what the device was before: not trusted after
        self._start_at(self._measured() or self.positions)

    def drive(self, frame: TickFrame | None, now: float, motion: Motion) -> bool:
        self._call(self.link.service)
        fw = self._firmware_state()
        if motion.move is Move.PARK:
            return self._park(motion, fw)
        self._check_device(fw)
        if motion.move is Move.HOME:
            if fw in (LinkState.SOFT_START, LinkState.RUNNING):
                self._start_at(self._measured() or self.positions)
                return True
            return False
        if motion.first:
            self._ramp_from = list(self.positions)
        saddle = self._saddle(frame)
        ease = (self._ramp_from, motion.elapsed) if motion.move is Move.SOFT_START else None
        self.state, out = pipeline.step(self.model, self.state, saddle, motion.dt, ease)
        self.aim = out.aim
        counts = target_counts(out.positions, self.units)
        with self._gate():
            self._call(lambda: self.link.send_targets(counts))
        self.positions = out.positions.tolist()
        self.counters["targets_sent"] += 1
        if motion.move is Move.SOFT_START:
            return fw is LinkState.RUNNING and motion.elapsed >= self.model.soft_start_s
        return False

    def outputs_off(self) -> None:
        t = self.link.telemetry
        latched = self.stops is not None and self.stops.latch.latched
        if not latched and t is not None and self._off_sent_with is not t and self._fresh_off(t):
            return  # a completed park: the firmware reports its outputs off
        self._off_sent_with = t
        self._we_latched = True
        self._call(lambda: self.link.send(link.EStop()))
        self.counters["estop_frames"] += 1

    def outputs_confirmed_off(self) -> bool:
        self._call(self.link.service)
        t = self.link.telemetry
        return t is not None and t is not self._off_sent_with and self._fresh_off(t)

    def on_fault(self, error: BaseException) -> None:
        """Nothing per actuator: the firmware parks all of them together."""

    def idle(self, now: float) -> None:
        """While not moving: keep the link alive (heartbeats, telemetry) and notice what the
        firmware did by itself (its e-stop input, a fault) or that it went silent."""
        if not self.is_open:
            return
        self._call(self.link.service)
        self._check_device(self._firmware_state())

    def takeover(self, pose: Sequence[float]) -> None:
        """Open the port another process drove (it is dead); the HELLO parks a moving device."""
        self._reset_session()
        if len(pose) == self.model.geometry.legs and all(map(math.isfinite, pose)):
            self.positions = list(pose)
        self.hello = self._call(self.link.open)
        self.counters["takeovers"] += 1

    def status(self) -> dict[str, Any]:
        """Firmware, link, actuators, workspace, limits hit and joints (:func:`plug_status.report`)."""
        return plug_status.report(
            model=self.model,
            serial=self.link,
            hello=self.hello,
            positions=self.positions,
            measured=self._measured(),
            state=self.state,
            aim=self.aim,
            saddle=self.saddle,
            faults_at_connect=self.faults_at_connect,
        )

    def tune(self, **changes: Any) -> None:
        """Live cueing parameters (intensity, cut-offs, ...): the running state blends toward them."""
        self.model = self.model.with_cueing(**changes)

    # -- inside ---------------------------------------------------------------------------

    def _reset_session(self) -> None:
        self._we_latched, self._reported_faults, self._silence_reported = False, 0, False
        self._off_sent_with = None
        self.faults_at_connect = []

    def _gate(self) -> Any:
        return contextlib.nullcontext() if self.stops is None else self.stops.gate()

    def _call(self, call: Callable[[], Any]) -> Any:
        """The link's errors as the lifecycle's (PortLost, PortBusy, NoReply, Mismatch, Rejected)."""
        with lifecycle_errors(self.counters):
            return call()

    def _check_hello(self, hello: link.HelloReply) -> None:
        legs = self.model.geometry.legs
        if hello.actuators != legs:
            raise Mismatch(0, f"{self.port}: the device drives {hello.actuators} actuators, {self.name} has {legs}")
        if self.expected_device and hello.device != self.expected_device:
            raise Mismatch(
                0, f"{self.port}: the device is {hello.device!r}, platform.device is {self.expected_device!r}"
            )
        self.needs_homing = hello.profile in HOMING_PROFILES

    def _measured(self) -> list[float] | None:
        t = self.link.telemetry
        if t is None or len(t.measured) != len(self.positions):
            return None
        return [c / (link.COUNTS_PER_UNIT * self.units) for c in t.measured]

    def _start_at(self, positions: Sequence[float]) -> None:
        """The follower at rest where the actuators are; the cue from scratch."""
        self.positions = list(positions)
        self._ramp_from = list(positions)
        self.state = pipeline.initial(self.model, positions)

    def _saddle(self, frame: TickFrame | None) -> list[float]:
        """The tick frame's saddle pose (m, deg, at the configured point); a bad one holds the last."""
        saddle = () if frame is None else frame.saddle
        if len(saddle) == len(SADDLE) and all(map(math.isfinite, saddle)):
            self.saddle = list(saddle)
        else:
            self.counters["bad_inputs"] += 1
        return self.saddle

    def _firmware_state(self) -> LinkState:
        """The device's state from its telemetry; CONNECTING until one newer than the arm arrives."""
        if self.link.telemetry is not None and self.link.telemetry is self._before_arm:
            return LinkState.CONNECTING
        return self.link.state

    def _check_device(self, fw: LinkState) -> None:
        """What the device did by itself: latched a fault or an e-stop; fell silent."""
        t = self.link.telemetry
        if fw in _LATCHED and t is not None and not (self._we_latched and fw is LinkState.ESTOP):
            faults = t.faults or 0xFFFF
            if faults != self._reported_faults:
                self._reported_faults = faults
                self.counters["firmware_faults"] += 1
                raise HardwareFault(
                    0, tuple(fault_names(t.faults)) or ("estop",), t.faults, what=f"{self.name} firmware"
                )
        if self.link.health is not Health.SILENT:
            self._silent_since, self._silence_reported = None, False
            return
        # Silent for silence_s while we kept sending: a device that stopped answering. (After a
        # stall of our own the device stops its telemetry until our next frame: not its fault.)
        now = time.monotonic()
        if self._silent_since is None:
            self._silent_since = now
        if not self._silence_reported and now - self._silent_since >= self.link.silence_s:
            self._silence_reported = True
            raise NoReply(None, f"{self.port}: no valid frame from the device for {2 * self.link.silence_s:g} s")

    def _park(self, motion: Motion, fw: LinkState) -> bool:
        """PARK once, then the firmware eases to its park pose; done when it reports its outputs off."""
        if motion.first:
            self._call(lambda: self.link.send(link.Park()))
            self.counters["park_frames"] += 1
        t = self.link.telemetry
        measured = self._measured()
        if measured is not None:
            self.positions = measured
        return t is not None and fw in _AT_REST and not t.flags & Flag.OUTPUTS_ON

    def _fresh_off(self, t: link.Telemetry) -> bool:
        return LinkState(t.state) in _AT_REST and not t.flags & Flag.OUTPUTS_ON


def describe(file: str, port: str | None) -> DeviceInfo:
    """The registry's hook: validate a platform file (ConfigError names file and key)."""
    cfg = load_platform(file)
    model = PlatformModel.from_config(cfg)
    legs = model.geometry.legs
    budget = (
        f"{cfg.name} on {port}: {legs} actuators, one TARGET of {8 + 2 * legs} bytes a tick "
        f"({model.geometry.kind.value}, cueing {cfg.cueing.preset} at {cfg.cueing.intensity:g} %)"
    )
    return DeviceInfo(cfg.name, 250.0, budget, consumes=frozenset({Part.SADDLE}))


def make_plug(spec: DeviceSpec) -> PlatformPlug:
    """The registry's hook: the plug for a planned platform (options from ``[platform]``)."""
    options = dict(spec.options)
    if spec.port is None:
        raise ValueError(f"{spec.name}: the platform needs a serial port")
    return PlatformPlug(
        PlatformModel.load(spec.file),
        spec.port,
        device=options.get("device"),
        heartbeat_ms=int(options.get("heartbeat_ms", 200)),
        period_s=spec.period_s,
    )
