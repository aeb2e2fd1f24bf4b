"""The rig device through the real dynamixel-sdk against the emulated bus: the normal path.

A horse trots through the rules into the 24-servo rig: connecting ends disarmed with
torque off, the arm soft-starts from where the servos are, the goals are the mapped
rule outputs, the servos follow them within a stated tolerance, every tick is one goal
write (+ the divided read), and disarm / close end with torque off.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import time
from collections.abc import Callable
from typing import Any

import pytest

from riderlive.channels import RIDER
from riderlive.devices.device import Device
from riderlive.devices.lifecycle import DeviceState, Refusal, Refused
from riderlive.devices.status import DeviceStatus
from riderlive.dynamixel.driver import rig_device
from riderlive.dynamixel.emulator import EmulatedBus
from riderlive.dynamixel.servo_map import ServoMap, deg_to_pulses, profile_velocity, pulses_to_deg
from riderlive.dynamixel.tables import Instruction, Item
from riderlive.horse import DEFAULT_SCALE, ProceduralHorse
from riderlive.rules import RiderModel
from tests.devices.memory_plug import rider_frame
from tests.dynamixel.rig_harness import (
    connect,
    drive,
    goal_deg,
    rig_of,
    servo_setups,
    short_rig,
    start_running,
    torque,
)
from tests.waiting import Pacer

S = DeviceState

TRACKING_LAG_DEG = 4.0
"""At every read while trotting, |goal sent - present position| may exceed the goal's
change since the goals the servo had a whole tick to act on (:func:`acted_goals`; the
tick's own step is ~2.5 deg at most for the seat and wrists at 50 Hz, more when the host
is late) by at most this: the servo's lag behind its 6000 deg/s^2 profile through the
kinks of the rule outputs."""
TRACKING_WITHIN_LAG = 0.95
"""Share of (read, servo) samples that must keep that bound (the 2-core CI box stalls)."""
TRACKING_MAX_DEG = 10.0
"""No sample beyond the goal's step + this. NOT true whatever the host does (issue 26):
after a late tick (a host stall of 100+ ms) the goals jump, ``drive`` ticks again at
once, and the emulator may process the jump late (seen: the jump's goal write reached
the emulator 30 ms after it was sent and 14 ms before the next read), so the servo had
~14 ms, not a tick, to act on it: reproduced 14.3 deg against a step of 0.8 deg. So the
bound is taken from the goal change since the last goal the emulator had a whole tick to
act on, on its own clock (:func:`acted_goals`)."""
GOAL_ADDRESS = 116
"""Goal Position's address (X series)."""
TRACKING_MEAN_DEG = 1.5
"""Mean |goal sent - present position| over servos and reads."""
FINAL_TOLERANCE_DEG = 0.5
"""Present position vs the last goal once the servos have settled."""


def trot() -> Callable[[float], list[float]]:
    """Rider frames of a trotting horse on its own clock (monotonic across drives)."""
    horse = ProceduralHorse("trot")
    model = RiderModel(scale=DEFAULT_SCALE)
    origin = time.perf_counter()
    return lambda _t: model.evaluate(horse.sample(time.perf_counter() - origin))


def extra(status: DeviceStatus, key: str) -> list[Any]:
    return [servo[key] for servo in status.extra["servos"]]


def acted_goals(bus: EmulatedBus, period_s: float) -> list[dict[int, list[float]]]:
    """For each read the emulator served (in order): per servo id, the goals (deg) it may
    still be acting on at that read: the last goal that reached it at least ``period_s``
    before the read (on the emulator's own clock) and every goal after it."""
    writes: list[tuple[float, dict[int, float]]] = []
    out: list[dict[int, list[float]]] = []
    for at, raw in list(bus.arrivals):
        if raw[7] == Instruction.SYNC_WRITE and int.from_bytes(raw[8:10], "little") == GOAL_ADDRESS:
            body = raw[12:-2]
            goals = {
                body[i]: pulses_to_deg(int.from_bytes(body[i + 1 : i + 5], "little", signed=True))
                for i in range(0, len(body), 5)
            }
            writes.append((at, goals))
        elif raw[7] in (Instruction.SYNC_READ, Instruction.FAST_SYNC_READ):
            acted = [i for i, (t, _) in enumerate(writes) if t <= at - period_s]
            window = writes[acted[-1] if acted else 0 :]
            ids = {sid for _, g in window for sid in g}
            out.append({sid: [g[sid] for _, g in window if sid in g] for sid in ids})
    return out


def test_trot_into_full_rider(bus_factory: Callable[..., EmulatedBus]) -> None:
    rig = short_rig(tick_hz=50.0, baud=4_000_000)
    bus = bus_factory(servo_setups(rig), baud=rig.bus.baud)
    device = rig_device(rig, port=bus.port)
    horse = trot()
    setup = connect(device)
    # connected, checked, configured as the map says, and torque OFF: nothing moves yet
    assert [t.target for s in setup.statuses for t in s.transitions] == [S.CONNECTING, S.DISARMED]
    bus.settle()
    for servo in rig.servos.values():
        assert bus.read_item(servo.id, Item.RETURN_DELAY_TIME) == 0
        assert bus.read_item(servo.id, Item.MIN_POSITION_LIMIT) == deg_to_pulses(servo.min_deg)
        assert bus.read_item(servo.id, Item.MAX_POSITION_LIMIT) == deg_to_pulses(servo.max_deg)
        assert bus.read_item(servo.id, Item.PROFILE_VELOCITY) == profile_velocity(servo.max_speed_dps)
        assert bus.read_item(servo.id, Item.BUS_WATCHDOG) == rig.bus.bus_watchdog_ms // 20
        assert torque(bus, servo.id) == 0
    quiet = drive(device, 0.3, horse)
    assert all(s.state is S.DISARMED and not s.wrote for s in quiet.statuses)
    assert all(s.outputs_off_confirmed for s in quiet.statuses[-3:])  # read back

    assert device.arm(rig.name, "test") is S.SOFT_START
    armed = drive(device, 3.0, horse, until=lambda s: s.state is not S.SOFT_START)
    assert device.state is S.RUNNING
    assert all(torque(bus, servo.id) == 1 for servo in rig.servos.values())
    assert armed.statuses[0].armed_by == "test"

    smap = ServoMap(rig)
    run = drive(device, 1.5, horse)  # the same trot, continued
    running = [(s, r) for s, r in zip(run.statuses, run.riders, strict=True) if s.state is S.RUNNING]
    assert len(running) > 40, [s.fault for s in run.statuses if s.fault][:1]
    reads = lagging = missed = 0
    errors: list[float] = []
    served = acted_goals(bus, 1.0 / rig.bus.tick_hz)
    served = served[len(served) - sum(1 for s, _ in running[1:] if s.extra["read"]) :]
    ids = [servo["id"] for servo in running[0][0].extra["servos"]]
    previous = goal_deg(running[0][0])
    transactions = running[0][0].extra["transactions"]
    for status, rider in running[1:]:
        goals = goal_deg(status)
        expected = smap.targets(rider, smap.park)
        assert goals == pytest.approx(expected, abs=1e-9)  # the rules, mapped, unclamped
        assert not any(extra(status, "clamped"))
        read = status.extra["read"]
        assert status.extra["transactions"] - transactions == (2 if read else 1)
        transactions = status.extra["transactions"]
        if read:
            acting = served[reads]
            reads += 1
            for sid, err, goal, before in zip(ids, extra(status, "tracking_error_deg"), goals, previous, strict=True):
                if err is None:  # that read missed this servo (retried next tick, counted)
                    missed += 1
                    continue
                assert acting[sid][-1] == pytest.approx(goal, abs=0.1)  # this tick's goal, then this read
                jump = max([abs(goal - before)] + [abs(goal - g) for g in acting.get(sid, [])])
                assert abs(err) < jump + TRACKING_MAX_DEG
                errors.append(abs(err))
                lagging += abs(err) > jump + TRACKING_LAG_DEG
        previous = goals
    assert reads >= len(running) // rig.bus.read_divider - 1
    assert missed <= 0.5 * (len(errors) + missed)  # a loaded 2-core box misses reads (retried, counted)
    assert sum(errors) / len(errors) < TRACKING_MEAN_DEG
    assert lagging <= (1.0 - TRACKING_WITHIN_LAG) * len(errors)
    last = running[-1][0]
    assert last.fault is None  # read failures (a loaded CI box) are retried within the budget
    assert last.counters["reads"] > last.counters.get("read_failures", 0)
    assert all(t is not None and 20 <= t < 80 for t in extra(last, "temperature_c"))
    assert all(v is not None and v > 4.0 for v in extra(last, "voltage_v"))
    published = json.loads(json.dumps(last.to_dict()))  # JSON-ready as it is
    assert published["state"] == "running" and published["servos"][0]["name"] == "lower_back_pitch"
    assert published["name"] == rig.name and published["kind"] == "dynamixel"
    assert published["servos"][6]["goal_deg"] == pytest.approx(goal_deg(last)[6])

    # the servos hold the last goal once the horse stops
    hold = run.riders[-1]
    drive(device, 0.4, lambda t: hold)
    for servo_id, goal in zip(smap.ids, goal_deg(device.tick(rider_frame(*hold), time.perf_counter())), strict=True):
        assert abs(pulses_to_deg(bus.read_item(servo_id, Item.PRESENT_POSITION)) - goal) < FINAL_TOLERANCE_DEG

    # disarm: ramp to the park pose, torque off, PARKED
    assert device.disarm("test") is S.PARKING
    parked = drive(device, 2.0, trot(), until=lambda s: s.state is not S.PARKING)
    assert device.state is S.PARKED
    bus.settle()
    assert goal_deg(parked.statuses[-1]) == pytest.approx(smap.park)
    for servo_id, park in zip(smap.ids, smap.park, strict=True):
        assert torque(bus, servo_id) == 0
        assert abs(pulses_to_deg(bus.read_item(servo_id, Item.PRESENT_POSITION)) - park) < 1.5
    device.close()
    assert device.state is S.DISCONNECTED


def bench_device(bus_factory: Callable[..., EmulatedBus], **bus: Any) -> tuple[Device, EmulatedBus]:
    rig = short_rig("bench3", **bus)
    emu = bus_factory(servo_setups(rig), baud=rig.bus.baud)
    return rig_device(rig, port=emu.port), emu


def test_soft_start_ramps_from_present_pose(bus_factory: Callable[..., EmulatedBus]) -> None:
    rig = short_rig("bench3", soft_start_s=0.5)
    emu = bus_factory([s.__class__(s.id, s.model, position=1700) for s in servo_setups(rig)], baud=rig.bus.baud)
    device = rig_device(rig, port=emu.port)
    rider = [0.0] * len(RIDER)
    connect(device)
    device.arm(rig.name, "test")
    run = drive(device, 3.0, lambda t: rider, until=lambda s: s.state is S.RUNNING)
    soft = [s for s in run.statuses if s.state is S.SOFT_START]
    took = run.statuses[-1].at - soft[0].at
    assert 0.5 - 0.01 <= took <= 0.5 + 0.3  # soft_start_s (+ a late tick on a loaded box)
    start = pulses_to_deg(1700)
    first, last = goal_deg(soft[0]), goal_deg(run.statuses[-1])
    assert first[0] == pytest.approx(start, abs=2.0)  # starts where the servo was
    assert last[0] == pytest.approx(180.0)  # ends on the rider's pose (channel 0 -> zero_deg)
    head = 2
    speed = rig.servos["head"].max_speed_dps
    for a, b in itertools.pairwise([*soft, run.statuses[-1]]):
        dt = min(b.at - a.at, 4.0 / rig.bus.tick_hz)
        assert abs(goal_deg(b)[head] - goal_deg(a)[head]) <= speed * dt + 1e-9  # no jump


def test_arming_soft_starts_from_where_a_hand_left_the_servo(bus_factory: Callable[..., EmulatedBus]) -> None:
    """Disarmed, a servo is moved by hand (torque off): the arm reads it there and eases from it."""
    device, emu = bench_device(bus_factory, soft_start_s=0.4)
    connect(device)
    with emu.lock:
        emu.servo(1).state = dataclasses.replace(emu.servo(1).state, position=2400.0)  # pushed to ~211 deg
    device.arm(device.name, "test")
    first = drive(device, 0.05).statuses[0]
    assert goal_deg(first)[0] == pytest.approx(pulses_to_deg(2400), abs=1.5)


def test_bad_rider_frames_are_held_not_raised(bus_factory: Callable[..., EmulatedBus]) -> None:
    device, _ = bench_device(bus_factory)
    start_running(device)
    rider, pacer = [1.0] * len(RIDER), Pacer(0.01)  # ticks at 100 Hz
    before = goal_deg(device.tick(rider_frame(*rider), time.perf_counter()))
    pacer.wait()
    bad = list(rider)
    bad[0] = math.nan
    status = device.tick(rider_frame(*bad), time.perf_counter())
    assert goal_deg(status)[0] == before[0]  # lower_back.rz held
    held = goal_deg(status)
    pacer.wait()
    status = device.tick(rider_frame(*[1.0, 2.0]), time.perf_counter())  # wrong length: everything held
    assert goal_deg(status) == pytest.approx(held, abs=1e-9)
    assert status.state is S.RUNNING
    assert status.counters["bad_inputs"] == 2


def test_limits_and_slew_are_applied(bus_factory: Callable[..., EmulatedBus]) -> None:
    device, emu = bench_device(bus_factory)
    start_running(device)
    rider = [0.0] * len(RIDER)
    rider[0] = 1000.0  # lower_back.rz far beyond max_deg
    run = drive(device, 3.0, lambda t: rider, until=lambda s: goal_deg(s)[0] >= 230.0 - 1e-9)
    goals = [goal_deg(s)[0] for s in run.statuses]
    assert run.statuses[0].extra["servos"][0]["clamped"]
    assert max(goals) == pytest.approx(230.0)  # max_deg of bench3's lower_back
    rig = rig_of(device)
    speed = rig.servos["lower_back"].max_speed_dps
    times = [s.at for s in run.statuses]
    for (t0, g0), (t1, g1) in itertools.pairwise(zip(times, goals, strict=True)):
        assert g1 - g0 <= speed * min(t1 - t0, 4.0 / rig.bus.tick_hz) + 1e-6
    emu.settle()
    assert emu.read_item(1, Item.GOAL_POSITION) <= deg_to_pulses(230.0)


def test_close_parks_then_torques_off_within_bound(bus_factory: Callable[..., EmulatedBus]) -> None:
    device, emu = bench_device(bus_factory)
    start_running(device)
    t0 = time.perf_counter()
    device.close()
    took = time.perf_counter() - t0
    assert device.state is S.DISCONNECTED
    emu.settle()
    bus = rig_of(device).bus
    assert took < device.plug.park_timeout_s + 0.2
    assert took >= bus.park_ramp_s * 0.9  # it did ease to the park pose (park_s less the wait for arrival)
    for servo_id in (1, 2, 3):
        assert torque(emu, servo_id) == 0
    assert abs(pulses_to_deg(emu.read_item(3, Item.GOAL_POSITION)) - 190.0) < 0.1  # head's park_deg


def test_requests_out_of_turn_are_refused_or_safe(bus_factory: Callable[..., EmulatedBus]) -> None:
    rig = short_rig(baud=4_000_000)  # 24 servos: configuring spans many ticks
    emu = bus_factory(servo_setups(rig), baud=rig.bus.baud)
    device = rig_device(rig, port=emu.port)
    device.connect("test")
    with pytest.raises(Refused) as refused:
        device.connect("test")  # already connecting
    assert refused.value.reason is Refusal.NOT_READY
    with pytest.raises(Refused) as refused:
        device.arm(rig.name, "test")  # not connected yet
    assert refused.value.reason is Refusal.NOT_READY
    drive(device, 2.0, until=lambda s: "configuring" in s.detail)
    assert device.disarm("test") is S.CONNECTING  # during setup nothing moves: the setup goes on
    run = drive(device, 5.0, until=lambda s: s.state is not S.CONNECTING)
    assert device.state is S.DISARMED, device.fault
    assert not any(status.wrote for status in run.statuses)  # no goal written
    emu.settle()
    assert all(torque(emu, i) == 0 for i in rig.ids)
    with pytest.raises(Refused) as refused:
        device.arm("bench3", "test")  # the name is the confirmation: not this rig
    assert refused.value.reason is Refusal.UNKNOWN_DEVICE
    device.arm(rig.name, "test")
    with pytest.raises(Refused) as refused:
        device.arm(rig.name, "test")  # double arm
    assert refused.value.reason is Refusal.ALREADY_ARMED
    drive(device, 5.0, until=lambda s: s.state is S.RUNNING)
    with pytest.raises(Refused) as refused:
        device.reset("test")  # nothing latched
    assert refused.value.reason is Refusal.NOTHING_TO_RESET
    with pytest.raises(Refused) as refused:
        device.reconnect("test")  # moving
    assert refused.value.reason is Refusal.MOVING
    assert device.state is S.RUNNING
    assert device.counters["arms"] == 1
    device.close()
    assert device.state is S.DISCONNECTED
