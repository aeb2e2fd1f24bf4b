"""The tick's devices: rates fitted to the tick, requests answered, e-stops to all at once;
and the registry's plan for a real rig map (divide down, or refuse naming both rates)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator

import pytest

from riderlive.devices import board as board_module
from riderlive.devices import registry
from riderlive.devices.board import SafetyBoard
from riderlive.devices.latch import StopLatch, StopSource
from riderlive.devices.lifecycle import DeviceState
from riderlive.devices.registry import RateMismatch, plan
from riderlive.dynamixel.rig import RIG_DIR
from riderlive.realtime import commands as cmd
from riderlive.realtime.output import GUARDIAN_CHECK_S, TickDevices
from tests.devices.memory_plug import rider_frame
from tests.waiting import Pacer

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


def run(devices: TickDevices, ticks: int, start: int = 0, beat: bool = True) -> None:
    """Tick; ``beat``: the guardian on the board (if any) beats as its watch loop would."""
    board, pacer = devices.board, Pacer(0.001)
    for i in range(start, start + ticks):
        if beat and board is not None and board.guardian_pid:
            board.guardian_beat = time.perf_counter()
        devices.tick(rider_frame(1.0, tick=i, at=time.perf_counter()))
        pacer.wait()  # a 1 kHz tick


def run_past(devices: TickDevices, until_s: float, start: int, beat: bool = True) -> int:
    """Tick (as :func:`run`) until a tick's clock is past ``until_s`` (perf_counter s): the
    guardian watch looks every ``GUARDIAN_CHECK_S`` of that clock, so a loss before
    ``until_s - GUARDIAN_CHECK_S`` has been seen by then, whatever the host's load. Returns
    the number of ticks."""
    tick = start
    while True:
        at = time.perf_counter()
        run(devices, 1, tick, beat)
        tick += 1
        if at > until_s:
            return tick - start


def until(devices: TickDevices, wanted: dict[str, str], beat: bool = True, timeout: float = 5.0) -> None:
    tick, deadline = 0, time.perf_counter() + timeout
    while devices.states() != wanted and time.perf_counter() < deadline:
        run(devices, 2, tick, beat)
        tick += 2
    assert devices.states() == wanted


def test_requests_are_answered_and_refusals_change_nothing(tick_devices) -> None:  # type: ignore[no-untyped-def]
    devices, latch, board = tick_devices
    assert [s.divider for s in devices.specs] == [2, 2]  # 100 ticks/s devices on a 200 Hz tick
    run(devices, 40)
    assert devices.states() == {"left": "disarmed", "right": "disarmed"}
    assert devices.devices[0].counters["ticks"] == 20  # every 2nd tick
    assert board.device(0) is not None and board.device(0)[0] is S.DISARMED  # published for the guardian

    reply = devices.request(cmd.Arm("left", "test", 1))
    assert not reply.ok and reply.refusal == "no_guardian" and "guardian" in reply.message  # no guardian running
    board.guardian_ready, board.guardian_pid = 1.0, os.getpid()
    board.guardian_beat = time.perf_counter()
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


def running_then_killed(devices: TickDevices, guardian: subprocess.Popen[bytes]) -> None:
    """``guardian`` (a sleeping process) on the board, "left" armed and running, then the
    guardian killed (SIGKILL) and reaped."""
    board = devices.board
    assert board is not None
    board.guardian_pid, board.guardian_ready = guardian.pid, 1.0
    until(devices, {"left": "disarmed", "right": "disarmed"})
    assert devices.request(cmd.Arm("left", "test", 1)).ok
    until(devices, {"left": "running", "right": "disarmed"})
    os.kill(guardian.pid, signal.SIGKILL)
    guardian.wait(10)


def test_the_tick_watches_the_guardian_dead_or_hung_armed_devices_park_arming_is_refused(  # type: ignore[no-untyped-def]
    tick_devices, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 25, the watched watchman: a guardian killed (SIGKILL) while a device runs, then
    one that hangs (no heartbeat): each time the tick parks the armed devices itself
    (ease to park, outputs off), counts it, and refuses to arm until a guardian watches."""
    monkeypatch.setattr(board_module, "GUARDIAN_HANG_S", 0.15)
    devices, _, board = tick_devices
    guardian = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        running_then_killed(devices, guardian)
        killed = time.perf_counter()
        ticks = run_past(devices, killed + GUARDIAN_CHECK_S, 100, beat=False)
        assert devices.states()["left"] == "parking"  # on the next look, not after a timeout
        assert ticks <= 2 + int(GUARDIAN_CHECK_S / 0.001)  # ticks of 1 ms and more: one look's period
        left = devices.devices[0]
        assert left.life.history[-1].by.startswith(f"tick: the guardian {guardian.pid} is dead")
        assert time.perf_counter() - killed < 0.5
        refused = devices.request(cmd.Arm("right", "test", 2))
        assert not refused.ok and refused.refusal == "no_guardian" and "dead" in refused.message
        until(devices, {"left": "parked", "right": "disarmed"}, beat=False)
        plug = left.plug
        assert not any(plug.outputs) and plug.goals == [0.0] * 3  # type: ignore[attr-defined]
        status = devices.status()["guardian"]
        assert status["alive"] is False and "dead" in status["lost"]
        assert (status["losses"], status["stops"], status["arms_refused"]) == (1, 1, 1)
        assert left.counters["guardian_stops"] == 1

        board.guardian_pid = os.getpid()  # a new guardian: arming is allowed again
        run(devices, 10, 200)  # more than GUARDIAN_CHECK_S
        assert devices.status()["guardian"]["alive"] and devices.status()["guardian"]["lost"] is None
        assert devices.states()["left"] == "parked"  # nothing re-arms by itself
        assert devices.request(cmd.Arm("left", "test", 3)).ok
        until(devices, {"left": "running", "right": "disarmed"})
        hung_from = board.guardian_beat  # its last beat: it stops beating (SIGSTOP, a stuck loop)
        while devices.states()["left"] == "running" and time.perf_counter() - hung_from < 5.0:
            run(devices, 1, 300, beat=False)
        assert devices.states()["left"] == "parking" and 0.15 <= time.perf_counter() - hung_from < 1.0
        assert "hung" in (devices.guardian_lost or "")
        assert devices.status()["guardian"]["losses"] == 2 and left.counters["guardian_stops"] == 2
    finally:
        guardian.kill()
        guardian.wait(10)


def test_a_guardian_killed_during_arming_parks_the_soft_start_and_nothing_moves_after(  # type: ignore[no-untyped-def]
    tick_devices,
) -> None:
    """The guardian dies between the arm's acceptance and the end of the soft start, twice
    in a row: each time the device parks from where it was, and stays parked."""
    devices, _, board = tick_devices
    for attempt in (1, 2):
        guardian = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
        try:
            board.guardian_pid, board.guardian_ready = guardian.pid, 1.0
            until(devices, {"left": "parked" if attempt == 2 else "disarmed", "right": "disarmed"})
            assert devices.request(cmd.Arm("left", "test", attempt)).ok
            assert devices.states()["left"] == "soft_start"
            os.kill(guardian.pid, signal.SIGKILL)
            guardian.wait(10)
            run(devices, 12, 1000 * attempt, beat=False)  # > GUARDIAN_CHECK_S
            assert devices.states()["left"] in ("parking", "parked")
            until(devices, {"left": "parked", "right": "disarmed"}, beat=False)
            run(devices, 20, 2000 * attempt, beat=False)
            assert devices.states()["left"] == "parked"  # nothing re-arms
            assert not any(devices.devices[0].plug.outputs)  # type: ignore[attr-defined]
        finally:
            guardian.kill()
            guardian.wait(10)
    assert devices.guardian_losses == 2 and devices.devices[0].counters["guardian_stops"] == 2


def test_a_standby_that_takes_over_between_two_looks_still_parks_the_armed_devices(  # type: ignore[no-untyped-def]
    tick_devices,
) -> None:
    """The guardian that watched is replaced by its standby faster than the tick's 5 ms
    look: no gap is ever seen, but the pid changed: the same category 1 stop (counted);
    arming is allowed again at once (a guardian watches)."""
    devices, _, board = tick_devices
    first, standby = (subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"]) for _ in range(2))
    try:
        running_then_killed(devices, first)
        board.guardian_beat, board.guardian_pid = time.perf_counter(), standby.pid  # as stand_by does
        run(devices, 12, 500)
        assert devices.states()["left"] in ("parking", "parked")
        assert "standby" in devices.devices[0].life.history[-1].by or devices.states()["left"] == "parked"
        assert devices.guardian_losses == 1 and devices.devices[0].counters["guardian_stops"] == 1
        until(devices, {"left": "parked", "right": "disarmed"})
        assert devices.request(cmd.Arm("left", "test", 2)).ok  # a guardian watches: arming is allowed
    finally:
        for process in (first, standby):
            process.kill()
            process.wait(10)
