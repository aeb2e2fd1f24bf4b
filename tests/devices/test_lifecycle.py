"""The one lifecycle: its table, every transition, every refusal, faults and e-stops.

With an in-memory plug (tests/devices/memory_plug.py); the same on real servos through
the SDK and the emulator is in tests/dynamixel/test_driver*.py.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest

from riderlive.devices.device import Device
from riderlive.devices.latch import StopLatch, StopSource
from riderlive.devices.lifecycle import (
    ARMED,
    TRANSITIONS,
    DeviceState,
    FaultKind,
    HardwareFault,
    IllegalTransition,
    Lifecycle,
    NoReply,
    PortBusy,
    PortLost,
    Refusal,
    Refused,
    arm_refusal,
)
from riderlive.devices.plug import smoothstep
from tests.devices.memory_plug import MemoryPlug, rider_frame
from tests.waiting import Pacer

S = DeviceState
PERIOD = 0.01
NAMES = {s.value for s in DeviceState}


@pytest.fixture
def latch() -> Iterator[StopLatch]:
    shared = StopLatch()
    yield shared
    shared.close()


def make(latch: StopLatch, **plug: object) -> tuple[Device, MemoryPlug]:
    mem = MemoryPlug(**plug)  # type: ignore[arg-type]
    return Device(mem, PERIOD, latch), mem


def ticks(device: Device, n: int = 1, frame: tuple[float, ...] = (1.0,)) -> None:
    pacer = Pacer(PERIOD / 4)
    for _ in range(n):
        device.tick(rider_frame(*frame), time.perf_counter())
        pacer.wait()  # ticks four times faster than the device's period


def until(device: Device, state: DeviceState, limit: int = 200, frame: tuple[float, ...] = (1.0,)) -> None:
    for _ in range(limit):
        if device.state is state:
            return
        ticks(device, 1, frame)
    raise AssertionError(f"{device.state} is not {state}")


def connected(latch: StopLatch) -> tuple[Device, MemoryPlug]:
    device, mem = make(latch)
    device.connect("test")
    until(device, S.DISARMED)
    return device, mem


def test_the_names_are_those_of_the_lifecycle_document() -> None:
    assert {
        "disconnected", "connecting", "disarmed", "homing", "soft_start",
        "running", "parking", "parked", "estop", "fault",
    } == NAMES  # fmt: skip
    assert set(TRANSITIONS) == set(DeviceState)
    for source, targets in TRANSITIONS.items():
        if source is not S.ESTOP:
            assert S.ESTOP in targets, f"e-stop from {source}"
    # only an arm leaves disarmed/parked toward motion; nothing else enters an armed state
    into_motion = {(a, b) for a, ts in TRANSITIONS.items() for b in ts if b in ARMED and a not in ARMED}
    assert into_motion == {(a, b) for a in (S.DISARMED, S.PARKED) for b in (S.HOMING, S.SOFT_START)}
    assert TRANSITIONS[S.ESTOP] == {S.DISARMED, S.CONNECTING, S.DISCONNECTED}  # reset (or close) only


@pytest.mark.parametrize(
    ("name", "state", "latched", "reason"),
    [
        ("other", DeviceState.DISARMED, False, Refusal.UNKNOWN_DEVICE),
        ("mem", DeviceState.DISARMED, True, Refusal.ESTOPPED),  # the latch, whatever the state says
        ("mem", DeviceState.ESTOP, False, Refusal.ESTOPPED),
        ("mem", DeviceState.FAULT, False, Refusal.FAULTED),
        ("mem", DeviceState.RUNNING, False, Refusal.ALREADY_ARMED),
        ("mem", DeviceState.SOFT_START, False, Refusal.ALREADY_ARMED),
        ("mem", DeviceState.PARKING, False, Refusal.PARKING),
        ("mem", DeviceState.CONNECTING, False, Refusal.NOT_READY),
        ("mem", DeviceState.DISCONNECTED, False, Refusal.NOT_READY),
    ],
)
def test_arm_refusal_says_why(name: str, state: DeviceState, latched: bool, reason: Refusal) -> None:
    refused = arm_refusal("mem", name, state, latched, "servo 2 overheated")
    assert refused is not None and refused.reason is reason
    if reason is Refusal.FAULTED:
        assert "servo 2 overheated" in str(refused)


@pytest.mark.parametrize("state", [DeviceState.DISARMED, DeviceState.PARKED])
def test_arm_refusal_lets_an_arm_by_name_from_rest(state: DeviceState) -> None:
    assert arm_refusal("mem", "mem", state, False, "none") is None


def test_lifecycle_refuses_illegal_transitions_and_records_who_asked() -> None:
    life = Lifecycle(name="rig")
    with pytest.raises(IllegalTransition):
        life.go(S.RUNNING, 0.0, "skip the checks", "test")
    life.go(S.CONNECTING, 1.0, "connect", "tick")
    life.go(S.DISARMED, 1.5, "configured", "setup")
    life.go(S.ESTOP, 2.0, "button", "rest 127.0.0.1")
    with pytest.raises(IllegalTransition):
        life.go(S.RUNNING, 3.0, "e-stop is latched", "test")
    with pytest.raises(IllegalTransition):
        life.go(S.SOFT_START, 3.0, "reset never arms", "test")
    drained = life.drain()
    assert [t.target for t in drained] == [S.CONNECTING, S.DISARMED, S.ESTOP]
    assert life.drain() == ()
    assert drained[2].to_dict() == {
        "at": 2.0,
        "from": "disarmed",
        "to": "estop",
        "reason": "button",
        "by": "rest 127.0.0.1",
    }


def test_connect_ends_disarmed_with_outputs_off_and_read_back(latch: StopLatch) -> None:
    device, mem = make(latch)
    assert mem.outputs == [True] * 3  # left on by a previous owner
    device.connect("test")
    assert device.state is S.CONNECTING
    until(device, S.DISARMED)
    assert mem.outputs == [False] * 3 and mem.counters["goal_writes"] == 0
    status = device.tick(rider_frame(1.0), time.perf_counter())
    assert status.outputs_off_confirmed and not status.wrote
    ticks(device, 20)
    assert device.state is S.DISARMED and mem.counters["goal_writes"] == 0  # nothing moves unasked


def test_disarm_while_connecting_lets_the_setup_end_disarmed(latch: StopLatch) -> None:
    """A stop (the stage heartbeat lost, a web timeout) that meets a tick just restarted:
    nothing moves while connecting, so the setup goes on; the device must not be left
    disconnected, where neither reset nor arm could bring it back."""
    device, mem = make(latch)
    device.connect("test")
    assert device.state is S.CONNECTING
    assert device.disarm("stage heartbeat lost") is S.CONNECTING
    until(device, S.DISARMED)
    assert mem.outputs == [False] * 3 and mem.counters["goal_writes"] == 0
    assert device.arm("mem", "test") is S.SOFT_START  # an operator can arm it again


def test_arm_soft_starts_runs_and_disarm_parks(latch: StopLatch) -> None:
    device, mem = connected(latch)
    assert device.arm("mem", "rest 127.0.0.1 (page)") is S.SOFT_START
    assert mem.outputs == [True] * 3
    status = device.tick(rider_frame(1.0), time.perf_counter())
    assert status.armed_by == "rest 127.0.0.1 (page)" and status.wrote
    until(device, S.RUNNING)
    ticks(device, 3)
    assert mem.goals == [1.0] * 3
    assert device.disarm("test") is S.PARKING
    until(device, S.PARKED)
    assert mem.goals == [0.0] * 3 and mem.outputs == [False] * 3
    assert device.arm("mem", "test") is S.SOFT_START  # parked: may be armed again
    assert device.counters["arms"] == 2 and device.counters["disarms"] == 1


@pytest.mark.parametrize(
    ("prepare", "name", "reason"),
    [
        ("disarmed", "other", Refusal.UNKNOWN_DEVICE),
        ("connecting", "mem", Refusal.NOT_READY),
        ("disconnected", "mem", Refusal.NOT_READY),
        ("running", "mem", Refusal.ALREADY_ARMED),
        ("soft_start", "mem", Refusal.ALREADY_ARMED),
        ("parking", "mem", Refusal.PARKING),
        ("estop", "mem", Refusal.ESTOPPED),
        ("fault", "mem", Refusal.FAULTED),
    ],
)
def test_arm_refusals_change_nothing(latch: StopLatch, prepare: str, name: str, reason: Refusal) -> None:
    device, mem = make(latch, soft_start_s=1.0)
    if prepare != "disconnected":
        device.connect("test")
    if prepare not in ("disconnected", "connecting"):
        until(device, S.DISARMED)
    if prepare in ("running", "soft_start", "parking"):
        device.arm("mem", "test")
        if prepare == "running":
            mem.soft_start_s = 0.0
            until(device, S.RUNNING)
    if prepare == "parking":
        device.disarm("test")
    if prepare == "estop":
        device.estop()
    if prepare == "fault":
        mem.fail_next["confirm"] = PortLost("unplugged")
        ticks(device, 2)
    before, outputs = device.state, list(mem.outputs)
    with pytest.raises(Refused) as refused:
        device.arm(name, "test")
    assert refused.value.reason is reason
    assert device.state is before and mem.outputs == outputs


def test_estop_from_every_state_is_latched_and_reset_never_arms(latch: StopLatch) -> None:
    for state in (S.DISCONNECTED, S.CONNECTING, S.DISARMED, S.SOFT_START, S.RUNNING, S.PARKING, S.PARKED, S.FAULT):
        device, mem = make(latch)
        if state is not S.DISCONNECTED:
            device.connect("test")
        if state not in (S.DISCONNECTED, S.CONNECTING):
            until(device, S.DISARMED)
        if state in (S.SOFT_START, S.RUNNING, S.PARKING, S.PARKED):
            device.arm("mem", "test")
            if state is not S.SOFT_START:
                until(device, S.RUNNING)
            if state in (S.PARKING, S.PARKED):
                device.disarm("test")
            if state is S.PARKED:
                until(device, S.PARKED)
        if state is S.FAULT:
            mem.fail_next["confirm"] = NoReply(1, "silent")  # unconfirmed, not a fault...
            ticks(device, 1)
            device.plug.fail_next["confirm"] = PortLost("gone")  # type: ignore[attr-defined]
            ticks(device, 60)
        assert device.state is state, (state, device.state)
        latch.request(StopSource.REST)
        ticks(device, 1)
        assert device.state is S.ESTOP
        assert not any(mem.outputs) or state in (S.DISCONNECTED, S.CONNECTING)  # transport not open yet
        goals = mem.counters["goal_writes"]
        ticks(device, 5)
        assert device.state is S.ESTOP and mem.counters["goal_writes"] == goals
        assert device.last_stop is not None and device.last_stop.source == "rest"
        with pytest.raises(Refused):
            device.arm("mem", "test")
        reset = device.reset("operator")
        assert reset in (S.DISARMED, S.CONNECTING)
        until(device, S.DISARMED)
        ticks(device, 5)
        assert device.state is S.DISARMED and not any(mem.outputs)  # nothing moves
        device.close()


def test_reset_refusals_and_reset_during_parking(latch: StopLatch) -> None:
    device, _mem = connected(latch)
    with pytest.raises(Refused) as refused:
        device.reset("test")
    assert refused.value.reason is Refusal.NOTHING_TO_RESET
    device.arm("mem", "test")
    device.disarm("test")
    assert device.state is S.PARKING
    with pytest.raises(Refused) as refused:
        device.reset("test")
    assert refused.value.reason is Refusal.PARKING
    until(device, S.PARKED)


def test_a_fault_while_armed_parks_first_then_latches(latch: StopLatch) -> None:
    device, mem = connected(latch)
    device.arm("mem", "test")
    until(device, S.RUNNING)
    mem.fail_next["drive"] = HardwareFault(2, ("overload",), 0x20)
    ticks(device, 1)
    assert device.state is S.PARKING  # category 1: ease to park first
    assert device.fault is not None and device.fault.kind is FaultKind.HARDWARE_ERROR and device.fault.unit == 2
    assert "first aid: HardwareFault" in mem.log
    until(device, S.FAULT)
    assert mem.goals == [0.0] * 3 and not any(mem.outputs)
    assert device.counters["fault_hardware_error"] == 1
    assert device.reset("test") is S.CONNECTING  # a fault is checked again
    until(device, S.DISARMED)
    assert device.fault is None


def test_a_lost_port_cannot_park_faults_at_once(latch: StopLatch) -> None:
    device, mem = connected(latch)
    device.arm("mem", "test")
    until(device, S.RUNNING)
    mem.fail_next["drive"] = PortLost("unplugged")
    ticks(device, 1)
    assert device.state is S.FAULT and not mem.open
    assert device.fault is not None and device.fault.kind is FaultKind.PORT_LOST


def test_a_port_held_by_another_process_is_waited_for(latch: StopLatch) -> None:
    device, mem = make(latch)
    mem.fail_next["open"] = PortBusy("held by the guardian")
    device.connect("test")
    ticks(device, 1)
    assert device.state is S.CONNECTING and "held by the guardian" in device.detail
    until(device, S.DISARMED)
    assert device.counters["port_busy"] == 1 and device.fault is None


def test_a_port_held_for_good_ends_in_a_setup_timeout_fault_not_connecting_forever(
    latch: StopLatch, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 25: a generation stayed ``connecting`` for 100 s behind a held port."""
    from riderlive.devices import setup_run as setup_module

    monkeypatch.setattr(setup_module, "SETUP_TIMEOUT_S", 0.1)
    device, mem = make(latch)

    class Held(dict[str, BaseException]):
        def pop(self, key: str, default: object = None) -> BaseException | None:  # type: ignore[override]
            return PortBusy("held by pid 4242") if key == "open" else None

    mem.fail_next = Held()
    device.connect("test")
    started = time.perf_counter()
    until(device, S.FAULT, limit=400)
    assert 0.1 <= time.perf_counter() - started < 1.0
    assert device.fault is not None and device.fault.kind is FaultKind.SETUP_TIMEOUT
    assert "held by pid 4242" in device.fault.message and not mem.open
    assert device.counters["fault_setup_timeout"] == 1 and device.counters["port_busy"] >= 2
    with pytest.raises(Refused):
        device.arm("mem", "test")  # a fault: reset first
    mem.fail_next = {}
    assert device.reset("test") is S.CONNECTING
    until(device, S.DISARMED)  # the port is free again: a reset connects (never arms)
    assert not any(mem.outputs)


def test_a_latched_estop_survives_a_new_device(latch: StopLatch) -> None:
    """A restarted tick builds new devices: they come up in estop while the latch is set."""
    latch.request(StopSource.SIGNAL)
    device, mem = make(latch)
    device.connect("test")
    until(device, S.ESTOP)
    assert not any(mem.outputs)
    with pytest.raises(Refused) as refused:
        device.arm("mem", "test")
    assert refused.value.reason is Refusal.ESTOPPED
    assert device.reset("test") is S.DISARMED
    assert not latch.latched


def test_unconfirmed_outputs_off_is_repeated(latch: StopLatch) -> None:
    device, mem = connected(latch)
    device.arm("mem", "test")
    until(device, S.RUNNING)
    mem.confirm = False  # units that do not report off
    device.estop()
    ticks(device, 24)  # 60 ms: read back every tick (10 ms) while unconfirmed
    assert device.last_stop is not None and device.last_stop.confirmed_at is None
    assert device.last_stop.repeats >= 4 and mem.log.count("off") >= 5
    mem.confirm = True
    ticks(device, 8)
    assert device.last_stop.confirmed_at is not None
    assert device.tick(rider_frame(1.0), time.perf_counter()).outputs_off_confirmed


def test_takeover_parks_a_moving_device_from_its_last_pose(latch: StopLatch) -> None:
    device, mem = make(latch)
    device.takeover([0.8, 0.8, 0.8], moving=True)
    assert device.state is S.PARKING and mem.goals == [0.8] * 3
    ticks(device, 1)
    assert all(0.0 <= g <= 0.8 for g in mem.goals)
    until(device, S.PARKED)
    assert mem.goals == [0.0] * 3 and not any(mem.outputs)
    idle, mem2 = make(latch)
    idle.takeover([0.3] * 3, moving=False)
    assert idle.state is S.DISARMED and not any(mem2.outputs) and mem2.counters["goal_writes"] == 0


def test_smoothstep_ends() -> None:
    assert smoothstep(-1.0) == 0.0
    assert smoothstep(0.5) == 0.5
    assert smoothstep(2.0) == 1.0
