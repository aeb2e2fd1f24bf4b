"""The hand-back rule (riderlive/devices/guardians.py): after a failover the new generation
ticks at once, but its devices do not touch their transports until the guardian has handed
the dead generation's back; the supervisor waits only for the guardian to *begin* that stop.

On a real safety board (shared memory) with the tick's own :class:`TickDevices` and the
in-memory plug: held -> ``connecting`` with the guardian's report, nothing opened, nothing
published over the guardian's slots; handed back -> connected, ``disarmed``, never armed;
never handed back -> a fault at the bound, the transport untouched, a reset connects.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from collections.abc import Iterator

import pytest

from riderlive.devices import registry
from riderlive.devices.board import GuardianReport, SafetyBoard
from riderlive.devices.guardian import Guardian
from riderlive.devices.guardians import Guardians, GuardianTimes, handback_pending, handback_wanted, stop_wait_s
from riderlive.devices.latch import StopLatch, StopSource
from riderlive.devices.lifecycle import DeviceState, FaultKind
from riderlive.devices.registry import plan
from riderlive.realtime import commands as cmd
from riderlive.realtime.output import TickDevices
from tests.devices.memory_plug import MemoryPlug, rider_frame
from tests.waiting import Pacer, wait_until

S = DeviceState


@pytest.fixture
def board() -> Iterator[SafetyBoard]:
    board = SafetyBoard()
    yield board
    board.close()


def test_the_rule_waits_while_the_named_generation_is_not_handed_back(board: SafetyBoard) -> None:
    assert handback_pending(board, 0) is None  # no failover: nothing to wait for
    board.handback_from, board.guardian_done = 3, 2
    board.report(0, GuardianReport.PARKING)
    expected = "waiting for the guardian to park and hand back generation 3 (guardian: parking)"
    assert handback_pending(board, 0) == expected
    board.report(0, GuardianReport.OUTPUTS_OFF)  # its device is off, the stop has not ended (another device parks)
    assert "generation 3 (guardian: outputs off)" in str(handback_pending(board, 0))
    board.guardian_done = 3
    assert handback_pending(board, 0) is None
    board.handback_from = 4  # a later failure names a later generation
    assert handback_pending(board, 0) is not None


class _Running:
    """A guardian process as ``Guardians`` sees it (only whether one is kept matters here)."""

    pid = 1


def test_the_supervisor_waits_for_the_stop_to_begin_not_to_end(board: SafetyBoard) -> None:
    guardians = Guardians(board, "latch", (), GuardianTimes(0.1, 1.0))
    assert guardians.taken(5) and guardians.stopped(5)  # no guardian kept: nothing to wait for
    guardians.guardian = _Running()  # type: ignore[assignment]
    board.guardian_done = 4
    assert not guardians.taken(5) and not guardians.stopped(5)
    board.guardian_taking = 5  # the dead tick killed, its devices' last poses read: the park goes on
    assert guardians.taken(5) and not guardians.stopped(5)
    board.guardian_done = 5
    assert guardians.taken(5) and guardians.stopped(5)
    assert guardians.stop_wait_s(5.0) == stop_wait_s(5.0) == 5.0 + 3.0 + 5.0


def test_the_hand_back_is_awaited_only_while_a_guardian_parks() -> None:
    assert handback_wanted(7, taken=True, stopped=False) == 7  # parking: the new devices wait
    assert handback_wanted(7, taken=True, stopped=True) == 0  # handed back already
    # nobody began the stop by the bound: nobody will park; waiting would leave the rig
    # holding its last goal with torque on, so the new devices connect and turn it off
    assert handback_wanted(7, taken=False, stopped=False) == 0


@pytest.fixture
def after_failover(monkeypatch: pytest.MonkeyPatch, board: SafetyBoard) -> Iterator[tuple[SafetyBoard, StopLatch]]:
    """The board as the supervisor leaves it when it promotes generation 2 while the guardian
    parks generation 1's devices: a watching guardian, ``handback_from`` 1."""
    monkeypatch.setitem(registry.KINDS, "memory", "tests.devices.memory_plug")
    latch = StopLatch()
    board.guardian_ready, board.guardian_pid, board.guardian_beat = 1.0, os.getpid(), time.perf_counter()
    board.guardian_taking, board.handback_from, board.guardian_done = 1, 1, 0
    board.report(0, GuardianReport.PARKING)
    board.publish(0, S.PARKING, [0.25, 0.25, 0.25])  # the guardian's park, published for a successor
    yield board, latch
    latch.close()


def tick_for(devices: TickDevices, board: SafetyBoard, seconds: float, start: int = 0) -> int:
    """Tick at 1 kHz for ``seconds`` of the clock (the guardian beating); the ticks run."""
    pacer, tick, end = Pacer(0.001), start, time.perf_counter() + seconds
    while time.perf_counter() < end:
        board.guardian_beat = time.perf_counter()
        devices.tick(rider_frame(1.0, tick=tick, at=time.perf_counter()))
        tick += 1
        pacer.wait()
    return tick


def plugs(devices: TickDevices) -> list[MemoryPlug]:
    return [d.plug for d in devices.devices]  # type: ignore[misc]


def test_held_waits_untouched_then_connects_disarmed_and_never_arms(
    after_failover: tuple[SafetyBoard, StopLatch],
) -> None:
    board, latch = after_failover
    specs = [plan("memory", name, None, tick_hz=200.0)[0] for name in ("left", "right")]
    devices = TickDevices(specs, latch, board, guardian_required=True)
    devices.open(handback_bound_s=60.0)
    tick = tick_for(devices, board, 0.1)
    assert devices.states() == {"left": "connecting", "right": "connecting"}
    shown = devices.status()["devices"][0]
    assert shown["detail"] == "waiting for the guardian to park and hand back generation 1 (guardian: parking)"
    assert shown["counters"]["handback_waits"] == 1
    assert all(not p.open and p.log == [] and p.outputs == [True] * 3 for p in plugs(devices))  # untouched
    assert board.device(0) == (S.PARKING, [0.25, 0.25, 0.25])  # the guardian's slot, not overwritten
    assert board.device(1) is None
    reply = devices.request(cmd.Arm("left", "test", 1))
    assert not reply.ok and reply.refusal == "not_ready"  # nothing arms while connecting
    latch.request(StopSource.REST)  # an e-stop and a reset meanwhile: still no transport touched
    assert devices.act_on_stop(time.perf_counter()) and devices.states()["left"] == "estop"
    assert devices.request(cmd.Reset(None, "test", 2)).ok
    tick = tick_for(devices, board, 0.05, tick)
    assert devices.states() == {"left": "connecting", "right": "connecting"}
    assert all(not p.open and "setup" not in p.log for p in plugs(devices))

    board.report(0, GuardianReport.OUTPUTS_OFF)
    board.guardian_done = 1  # handed back
    tick = tick_for(devices, board, 0.1, tick)
    assert devices.states() == {"left": "disarmed", "right": "disarmed"}
    assert all(p.log == ["setup"] and p.outputs == [False] * 3 for p in plugs(devices))  # connected: outputs off
    assert board.device(0) is not None and board.device(0)[0] is S.DISARMED  # published from here
    tick_for(devices, board, 0.2, tick)
    assert devices.states() == {"left": "disarmed", "right": "disarmed"}  # never re-armed
    assert all(d.counters["arms"] == 0 and d.counters["handback_timeouts"] == 0 for d in devices.devices)
    devices.close()


def test_never_handed_back_faults_at_the_bound_untouched_and_a_reset_connects(
    after_failover: tuple[SafetyBoard, StopLatch],
) -> None:
    board, latch = after_failover
    devices = TickDevices([plan("memory", "left", None, tick_hz=200.0)[0]], latch, board, guardian_required=True)
    bound = 0.1
    devices.open(handback_bound_s=bound)
    opened = time.perf_counter()
    tick = 0
    while devices.states()["left"] == "connecting":
        assert time.perf_counter() - opened < bound + 5.0, "still connecting long past the bound"
        tick = tick_for(devices, board, 0.01, tick)
    assert time.perf_counter() - opened >= bound
    device = devices.devices[0]
    assert device.state is S.FAULT and device.fault is not None and device.fault.kind is FaultKind.SETUP_TIMEOUT
    assert "not connected: waiting for the guardian to park and hand back generation 1" in device.fault.message
    assert device.counters["handback_timeouts"] == 1
    plug = plugs(devices)[0]
    # never opened: no outputs-off in the middle of a park (the lifecycle's first-aid hook saw the fault, no transport)
    assert not plug.open and plug.log == ["first aid: HandbackTimeout"] and plug.outputs == [True] * 3
    reply = devices.request(cmd.Reset("left", "test", 1))  # the operator's call: connect without waiting
    assert reply.ok
    tick_for(devices, board, 0.1, tick)
    assert devices.states() == {"left": "disarmed"} and plug.outputs == [False] * 3 and device.counters["arms"] == 0
    devices.close()


def test_a_stop_left_unfinished_by_a_dead_guardian_is_finished_without_killing_the_next_tick(
    monkeypatch: pytest.MonkeyPatch, board: SafetyBoard
) -> None:
    """The guardian died in the middle of generation 1's park after the next generation was
    promoted (its devices waiting for the hand-back): its successor finishes that park from
    the progress on the board, and does not kill the serving tick."""
    monkeypatch.setitem(registry.KINDS, "memory", "tests.devices.memory_plug")
    latch = StopLatch()
    serving = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])  # generation 2's tick
    try:
        now = time.perf_counter()
        board.web_pid, board.web_beat = os.getpid(), now
        board.tick_pid, board.tick_generation, board.tick_beat = serving.pid, 2, now
        board.guardian_taking, board.guardian_done, board.handback_from = 1, 0, 1
        board.publish(0, S.PARKING, [0.3, 0.3, 0.3])  # where the dead guardian's park had got
        spec = plan("memory", "left", None, tick_hz=100.0)[0]
        guardian = Guardian(board, latch, [spec], tick_timeout_s=60.0, web_timeout_s=60.0)
        runner = threading.Thread(target=guardian.run)
        runner.start()
        wait_until(lambda: board.guardian_done == 1, 10.0, "the unfinished stop was not finished")
        board.shutdown = 1.0
        runner.join(5.0)
        assert board.reported(0) is GuardianReport.OUTPUTS_OFF and handback_pending(board, 0) is None
        assert serving.poll() is None, "the serving tick was not killed"
        assert board.guardian_takeovers == 1
    finally:
        serving.kill()
        serving.wait()
        latch.close()
