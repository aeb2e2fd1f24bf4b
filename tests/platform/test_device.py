"""The platform as a device, end to end: the lifecycle driving firmware_proto's host build (the
real C program on a pty) over the real serial link, fed by the procedural horse's trot.

Arming, homing, the soft start, running, the latched e-stop, reset, the eased return on
re-arm, the firmware's own dead-man, a vanished port and a wrong link version; every target
the firmware accepted is checked against the platform's limits."""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import pytest

from riderlive.devices.device import Device
from riderlive.devices.lifecycle import DeviceState, FaultKind, Refused
from riderlive.devices.status import DeviceStatus
from riderlive.horse import ProceduralHorse
from riderlive.platform import link_vocab
from riderlive.platform.device import PlatformPlug, describe
from riderlive.platform.firmware_host import FirmwareHost
from riderlive.platform.mechanism.pipeline import PlatformModel
from riderlive.saddle import SaddlePoint, saddle_from_horse
from riderlive.tickframe import Flag, Part, TickFrame
from tests.platform.fake_device import FakeDevice, reply_hello

S = DeviceState
PERIOD = 0.01
COUNTS = 1e5  # counts per m of stroke (0.01 mm)


def horse_frame(horse: list[float], now: float, point: SaddlePoint | None = None) -> TickFrame:
    """The tick's frame of a horse in metres, its saddle at ``point`` (as the tick computes it)."""
    saddle = saddle_from_horse(horse, point)
    return TickFrame.build(0, now, now, now, Flag.PROCEDURAL, (), horse, saddle)


@dataclass
class Bench:
    """A Device on a PlatformPlug on a firmware host, ticked at 100 Hz with a trotting horse."""

    firmware: FirmwareHost
    soft_start_s: float = 1.0
    heartbeat_ms: int = 200
    sent: list[tuple[float, tuple[float, ...]]] = field(default_factory=list)
    """Every target sent: (tick time, positions in m of stroke)."""
    arms: list[int] = field(default_factory=list)
    """Where in ``sent`` each arm began (the follower restarts where the actuators are)."""
    states: list[DeviceState] = field(default_factory=list)

    def __post_init__(self) -> None:
        model = replace(PlatformModel.load("stewart_compact"), soft_start_s=self.soft_start_s)
        self.plug = PlatformPlug(model, self.firmware.port, heartbeat_ms=self.heartbeat_ms, period_s=PERIOD)
        self.device = Device(self.plug, PERIOD)
        self.horse = ProceduralHorse("trot")
        self.t0 = time.perf_counter()
        self.last: DeviceStatus | None = None

    def tick(self) -> DeviceStatus:
        now = time.perf_counter()
        before = self.plug.counters["targets_sent"]
        self.last = self.device.tick(horse_frame(self.horse.sample(now - self.t0), now), now)
        if self.plug.counters["targets_sent"] > before:
            self.sent.append((now, tuple(self.plug.positions)))
        if not self.states or self.states[-1] is not self.device.state:
            self.states.append(self.device.state)
        return self.last

    def arm(self) -> DeviceState:
        self.arms.append(len(self.sent))
        return self.device.arm("stewart_compact", "test")

    def check_within_limits(self) -> None:
        for start, end in zip(self.arms, [*self.arms[1:], len(self.sent)], strict=True):
            check_within_limits(self, self.sent[start:end])

    def run(self, seconds: float) -> None:
        self.until(lambda: False, seconds, fail=False)

    def until(self, done: Callable[[], bool], timeout: float, fail: bool = True) -> None:
        deadline = time.perf_counter() + timeout
        next_tick = time.perf_counter()
        while not done():
            if time.perf_counter() > deadline:
                if fail:
                    raise AssertionError(f"timed out in {self.device.state.value}: {self.device.fault_message()}")
                return
            self.tick()
            next_tick += PERIOD
            time.sleep(max(0.0, next_tick - time.perf_counter()))

    def state_is(self, state: DeviceState) -> Callable[[], bool]:
        return lambda: self.device.state is state


def accepted_targets(firmware: FirmwareHost, start: int = 0) -> list[list[int]]:
    return [
        e["positions"]
        for e in firmware.events[start:]
        if e["event"] == "rx" and e["type"] == link_vocab.FrameType.TARGET
    ]


def check_within_limits(bench: Bench, sent: list[tuple[float, tuple[float, ...]]]) -> None:
    """Every target inside the soft limits; every step within the speed and acceleration limits."""
    g = bench.plug.model.geometry
    speeds = [0.0] * g.legs
    for (t0, q0), (t1, q1) in zip(sent, sent[1:], strict=False):
        dt = min(t1 - t0, 4 * PERIOD)
        for i, (a, b) in enumerate(zip(q0, q1, strict=True)):
            assert g.lower[i] - 1e-9 <= b <= g.upper[i] + 1e-9
            v = (b - a) / dt
            assert abs(v) <= g.max_speed[i] * (1 + 1e-6)
            assert abs(v - speeds[i]) <= g.max_accel[i] * dt * (1 + 1e-6) + 1e-9
            speeds[i] = v


def test_nothing_moves_until_armed_then_it_follows_a_trot_and_stops_as_asked() -> None:
    with FirmwareHost("platform6", trace=True) as firmware:
        bench = Bench(firmware)
        bench.device.connect("test")
        bench.until(bench.state_is(S.DISARMED), 5.0)
        bench.run(0.3)  # the horse trots; nothing may move
        assert bench.device.state is S.DISARMED and bench.plug.counters["targets_sent"] == 0
        # Disarmed after the firmware's first telemetry: no outputs-off (a latching ESTOP) to
        # a firmware that was off all along (it once happened on a loaded machine).
        assert bench.plug.link.telemetry is not None and bench.plug.counters["estop_frames"] == 0
        fw = firmware.status()
        assert fw["state"] == "disarmed" and fw["outputs_on"] == 0 and not accepted_targets(firmware)
        configs = [e for e in firmware.events if e["event"] == "rx" and e["type"] == link_vocab.FrameType.CONFIG]
        soft_max = [e["value"] for e in configs if e["key"] == link_vocab.ConfigKey.SOFT_MAX]
        assert soft_max == [8000] * 6  # the platform file's 80 mm, in counts from retracted
        assert [e["value"] for e in configs if e["key"] == link_vocab.ConfigKey.VELOCITY_LIMIT] == [24000] * 6

        # arm: homing (the firmware's first arm), the soft start, running
        assert bench.arm() is S.HOMING
        bench.until(bench.state_is(S.RUNNING), 15.0)
        start = len(bench.sent)
        bench.run(2.0)
        assert bench.states[-4:] == [S.DISARMED, S.HOMING, S.SOFT_START, S.RUNNING]
        trot = bench.sent[start:]
        heave = [sum(q) / 6 for _, q in trot]
        assert max(heave) - min(heave) > 0.002  # the trot's heave reaches the actuators (2 mm+)
        status = bench.last.to_dict() if bench.last else {}
        platform = status["platform"]
        assert platform["firmware"]["state"] == "running" and 0.0 < platform["workspace_use"] < 1.0
        assert all(0.0 <= a["closeness"] <= 1.0 for a in platform["actuators"])

        # the firmware got exactly what was sent, within every limit
        bench.check_within_limits()
        got = accepted_targets(firmware)
        assert got == [[round(q * COUNTS) for q in qs] for _, qs in bench.sent]
        counters = firmware.status()["counters"]
        assert counters["clipped"] == 0 and counters["rx_crc"] == 0 and counters["rx_stale"] == 0

        # e-stop: latched, outputs cut at once, nothing accepted after it
        bench.device.estop()
        assert bench.device.state is S.ESTOP
        firmware.wait_event(lambda e: e["event"] == "state" and e["to"] == "estop", 2.0)
        bench.until(lambda: bool(bench.last and bench.last.outputs_off_confirmed), 2.0)
        mark = len(firmware.events)
        bench.run(0.3)
        assert bench.device.state is S.ESTOP and not accepted_targets(firmware, mark)
        with pytest.raises(Refused, match="reset first"):
            bench.device.arm("stewart_compact", "test")
        # reset: disarmed, and it never moves by itself
        assert bench.device.reset("test") is S.DISARMED
        bench.run(0.5)
        assert bench.device.state is S.DISARMED and not accepted_targets(firmware, mark)
        assert firmware.status()["outputs_on"] == 0

        # re-arm: the firmware's latch is cleared, it homes again and eases back over 1-5 s
        bench.arm()
        bench.until(bench.state_is(S.RUNNING), 15.0)
        soft = [e for e in firmware.events[mark:] if e["event"] == "state" and "soft_start" in (e["from"], e["to"])]
        eased_s = (soft[1]["t_ns"] - soft[0]["t_ns"]) / 1e9
        assert 1.0 <= eased_s <= 5.0 + 0.1, eased_s
        assert bench.plug.counters["firmware_resets"] == 1

        # disarm: the firmware parks itself and turns its outputs off
        bench.device.disarm("test")
        bench.until(bench.state_is(S.PARKED), 10.0)
        fw = firmware.status()
        assert fw["state"] == "parked" and fw["outputs_on"] == 0
        bench.check_within_limits()
        bench.device.close("test")


def test_silence_makes_the_firmware_park_by_itself_and_a_vanished_port_is_a_fault() -> None:
    with FirmwareHost("platform6") as firmware:
        bench = Bench(firmware)
        bench.device.connect("test")
        bench.until(bench.state_is(S.DISARMED), 5.0)
        bench.device.arm("stewart_compact", "test")
        bench.until(bench.state_is(S.RUNNING), 15.0)

        # the host stops (a hung tick): no frame for longer than the dead-man's 200 ms
        mark = len(firmware.events)
        stopped = time.monotonic_ns()
        step = firmware.wait_event(lambda e: e["event"] == "park_step", 2.0, mark)
        assert step["deadman"] == 1 and 0.199 <= (step["t_ns"] - step["last_rx_t_ns"]) / 1e9 <= 0.204 + 0.004
        assert step["t_ns"] > stopped
        bench.until(bench.state_is(S.FAULT), 10.0)
        assert bench.device.fault is not None and bench.device.fault.kind is FaultKind.HARDWARE_ERROR
        assert "link_timeout" in bench.device.fault.bits
        assert firmware.wait_event(lambda e: e["event"] == "state" and e["to"] == "fault", 5.0, mark)
        assert bench.device.counters["faults"] == 1  # reported once, not every tick
        bench.run(0.2)
        assert bench.device.counters["faults"] == 1

        # reset: connect again; the firmware's latched fault is cleared (counted), disarmed
        bench.device.reset("test")
        bench.until(bench.state_is(S.DISARMED), 5.0)
        assert bench.plug.counters["latch_cleared_at_connect"] == 1
        assert bench.plug.faults_at_connect == ["link_timeout"]

        # the port vanishes (a pulled USB adapter): fault at once, counted
        os.close(bench.plug.link._serial.fd)
        bench.until(bench.state_is(S.FAULT), 2.0)
        assert bench.device.fault is not None and bench.device.fault.kind is FaultKind.PORT_LOST
        assert bench.device.counters["fault_port_lost"] == 1 and bench.plug.link.counters["port_lost"] == 1
        assert firmware.status()["outputs_on"] == 0
        bench.device.close("test")


def test_a_device_speaking_another_version_is_refused_clearly() -> None:
    fake = FakeDevice(reply_hello(version=2))
    try:
        plug = PlatformPlug(PlatformModel.load("stewart_compact"), fake.port)
        device = Device(plug, PERIOD)
        device.connect("test")
        deadline = time.perf_counter() + 5.0
        while device.state is S.CONNECTING and time.perf_counter() < deadline:
            device.tick(None, time.perf_counter())
        assert device.state is S.FAULT and device.fault is not None and device.fault.kind is FaultKind.MISMATCH
        assert "v2" in device.fault.message and "v1" in device.fault.message
        assert [f.message.TYPE for f in fake.frames] == [link_vocab.FrameType.HELLO]  # nothing else was sent
        with pytest.raises(Refused, match="has a fault"):
            device.arm("stewart_compact", "test")
        device.close()
    finally:
        fake.vanish()


def test_describe_names_the_platform_and_its_input() -> None:
    info = describe("stewart_compact", "/dev/null")
    assert info.name == "stewart_compact" and info.consumes == {Part.SADDLE} and "6 actuators" in info.budget
