"""The tick's devices: rates fitted to the tick, requests answered, e-stops to all at once;
and the registry's plan for a real rig map (divide down, or refuse naming both rates)."""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest

from riderlive.devices import registry
from riderlive.devices.board import SafetyBoard
from riderlive.devices.latch import StopLatch, StopSource
from riderlive.devices.lifecycle import DeviceState
from riderlive.devices.registry import RateMismatch, plan
from riderlive.dynamixel.rig import RIG_DIR
from riderlive.realtime import commands as cmd
from riderlive.realtime.output import TickDevices
from tests.devices.memory_plug import rider_frame

S = DeviceState


def test_a_rig_validated_below_the_tick_rate_is_divided_down_or_refused() -> None:
    bench3 = str(RIG_DIR / "bench3.toml")  # validated for 100 ticks/s
    spec, text = plan("dynamixel", bench3, "/dev/ttyX", 120.0)
    assert (spec.divider, spec.name, spec.port) == (2, "bench3", "/dev/ttyX")
    assert spec.period_s == pytest.approx(2 / 120.0)
    assert "validated for 100 ticks/s but the service ticks at 120/s: driving it every 2 ticks" in text
    assert "wire per tick" in text  # the wire budget, printed at start
    assert plan("dynamixel", bench3, None, 100.0)[0].divider == 1
    assert plan("dynamixel", bench3, None, 300.0)[0].divider == 3
    with pytest.raises(RateMismatch, match=r"validated for 100 ticks/s but the service ticks at 120/s"):
        plan("dynamixel", bench3, None, 120.0, "refuse")
    with pytest.raises(ValueError, match="unknown device kind"):
        plan("stepper", bench3, None, 100.0)


@pytest.fixture
def tick_devices(monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[TickDevices, StopLatch, SafetyBoard]]:
    monkeypatch.setitem(registry.KINDS, "memory", "tests.devices.memory_plug")
    latch, board = StopLatch(), SafetyBoard()
    specs = [plan("memory", name, None, tick_hz=200.0)[0] for name in ("left", "right")]
    devices = TickDevices(specs, latch, board, guardian_required=True)
    devices.open()
    yield devices, latch, board
    devices.close()
    latch.close()
    board.close()


def run(devices: TickDevices, ticks: int, start: int = 0) -> None:
    for i in range(start, start + ticks):
        devices.tick(rider_frame(1.0, tick=i, at=time.perf_counter()))
        time.sleep(0.001)


def test_requests_are_answered_and_refusals_change_nothing(tick_devices) -> None:  # type: ignore[no-untyped-def]
    devices, latch, board = tick_devices
    assert [s.divider for s in devices.specs] == [2, 2]  # 100 ticks/s devices on a 200 Hz tick
    run(devices, 40)
    assert devices.states() == {"left": "disarmed", "right": "disarmed"}
    assert devices.devices[0].counters["ticks"] == 20  # every 2nd tick
    assert board.device(0) is not None and board.device(0)[0] is S.DISARMED  # published for the guardian

    reply = devices.request(cmd.Arm("left", "test", 1))
    assert not reply.ok and reply.refusal == "not_ready" and "guardian" in reply.message  # no guardian running
    board["guardian_ready"], board["guardian_pid"] = 1.0, float(__import__("os").getpid())
    reply = devices.request(cmd.Arm("middle", "test", 2))
    assert not reply.ok and reply.refusal == "unknown_device" and "'left', 'right'" in reply.message
    reply = devices.request(cmd.Arm("left", "test", 3))
    assert reply.ok and reply.states == {"left": "soft_start", "right": "disarmed"}
    tick, deadline = 40, time.perf_counter() + 5.0  # the soft start takes 50 ms of the clock, not of ticks
    while devices.states()["left"] == "soft_start" and time.perf_counter() < deadline:
        run(devices, 2, tick)
        tick += 2
    assert devices.states()["left"] == "running"
    reload = devices.request(cmd.Reload("left", "test", 4))
    assert not reload.ok and reload.refusal == "moving"

    latch.request(StopSource.REST)
    assert devices.stop_pending() and devices.act_on_stop(time.perf_counter())
    assert devices.states() == {"left": "estop", "right": "estop"}  # all at once, whatever the divider
    assert not devices.request(cmd.Arm("right", "test", 5)).ok
    reset = devices.request(cmd.Reset(None, "test", 6))
    assert reset.ok and not latch.latched
    assert devices.states() == {"left": "disarmed", "right": "disarmed"}  # never armed by a reset
    nothing = devices.request(cmd.Reset("left", "test", 7))
    assert not nothing.ok and nothing.refusal == "nothing_to_reset"
    assert devices.request(cmd.Reload("right", "test", 8)).ok
    assert devices.devices[1].counters["reloads"] == 1 and devices.devices[1].counters["resets"] == 1
    run(devices, 20, 80)
    assert devices.states()["right"] == "disarmed"
    assert devices.status()["devices"][0]["name"] == "left"


def test_a_device_consuming_a_part_the_tick_lacks_is_refused_at_plan_time(monkeypatch: pytest.MonkeyPatch) -> None:
    from riderlive.devices.registry import DeviceInfo, DeviceSpec
    from riderlive.tickframe import MissingPart, Part, computed_parts
    from tests.devices import memory_plug

    wants = frozenset({Part.RIDER, Part.ESTIMATE})
    monkeypatch.setitem(registry.KINDS, "memory", "tests.devices.memory_plug")
    monkeypatch.setattr(memory_plug, "describe", lambda file, port: DeviceInfo(file, 100.0, "", consumes=wants))
    with pytest.raises(MissingPart, match=r"'seat'.*'estimate'"):
        plan("memory", "seat", None, 100.0, computed=computed_parts(saddle_input=False))
    spec, _ = plan("memory", "seat", None, 100.0, computed=computed_parts(saddle_input=True))
    assert spec.consumes == ("estimate", "rider") and spec.parts == wants
    assert DeviceSpec.from_json(spec.to_json()) == spec
