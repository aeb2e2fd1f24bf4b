"""``riderlive rig``: checks a map, prints its wire budget, connects and drives it on the
emulator (the service's tick loop, ``riderlive/rig_drive.py``) only when armed; Ctrl-C is an
e-stop; a killed driver is parked by its guardian, a killed guardian replaced by its standby
(the tick parks the rig), a hung guardian parks the rig too."""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from riderlive.cli import main
from riderlive.devices.board import GUARDIAN_HANG_S
from riderlive.devices.shared import pid_alive
from riderlive.dynamixel.emulator import EmulatedBus
from riderlive.dynamixel.rig import RigConfig, load_rig
from riderlive.dynamixel.servo_map import pulses_to_deg
from riderlive.dynamixel.tables import Instruction, Item
from riderlive.rig_drive import drive
from riderlive.rig_operator import EXIT_ESTOP, EXIT_FAULT
from tests.dynamixel.rig_harness import is_torque_off_write, servo_setups
from tests.service.live_server import ROOT
from tests.waiting import wait_until

GOAL_POSITION = 116


def test_check_prints_map_and_budget(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["rig", "full_rider"]) == 0
    out = capsys.readouterr().out
    assert "24 servos" in out and "2.60 ms" in out and "385 ticks/s" in out
    assert "seat_lift" in out and "cog.ty" in out


def test_bad_map_names_the_key(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('[servos.a]\nid = 1\nmodel = "XL330-M288"\nchannel = "nope.rz"\n')
    assert main(["rig", str(bad)]) == 2
    out = capsys.readouterr().out
    assert f"{bad}: servos.a.channel: unknown rider channel 'nope.rz'" in out


def goal_writes(emu: EmulatedBus) -> list[tuple[float, bytes]]:
    return [(t, raw) for t, raw in list(emu.arrivals) if raw[7] == Instruction.SYNC_WRITE and raw[8] == GOAL_POSITION]


def test_drive_without_arm_moves_nothing_with_arm_runs_the_lifecycle(
    bus_factory: Callable[..., EmulatedBus], capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """In this process (the service's tick loop in pytest's main thread), no guardian."""
    path = rig_file(tmp_path)
    rig = load_rig(path)
    emu = bus_factory(servo_setups(rig), baud=rig.bus.baud)
    assert drive(str(path), emu.port, 1.0, "walk", guardian=False) == 0
    out = capsys.readouterr().out
    assert "connecting -> disarmed" in out and "Nothing moves without --arm" in out
    emu.settle()
    assert goal_writes(emu) == [] and all(emu.read_item(i, Item.TORQUE_ENABLE) == 0 for i in (1, 2, 3))

    assert drive(str(path), emu.port, 1.0, "walk", arm=True, guardian=False) == 0
    out = capsys.readouterr().out
    for step in ("disarmed -> soft_start: armed (by cli --arm)", "soft_start -> running", "running -> parking"):
        assert step in out
    assert "parking -> parked" in out and "closed; fault: none" in out
    emu.settle()
    assert goal_writes(emu) and all(emu.read_item(i, Item.TORQUE_ENABLE) == 0 for i in (1, 2, 3))


def rig_file(tmp_path: Path) -> Path:
    """bench3 with short ramps and generous budgets for a loaded machine."""
    text = (ROOT / "config" / "rigs" / "bench3.toml").read_text()
    for key, value in (("bus_watchdog_ms", "600"), ("soft_start_s", "0.3"), ("park_s", "0.5")):
        text = re.sub(rf"^{key} = .*$", f"{key} = {value}", text, flags=re.M)
    text = text.replace("[bus]\n", "[bus]\ntimeout_margin_ms = 20.0\n", 1)
    path = tmp_path / "bench3.toml"
    path.write_text(text)
    return path


def start_cli(path: Path, port: str, seen: list[str] | None = None) -> subprocess.Popen[str]:
    """``rig PATH --port PORT --drive 60 --arm`` in its own process, once its rig runs (the
    lines it printed until then into ``seen``)."""
    cli = subprocess.Popen(
        [sys.executable, "-m", "riderlive", "rig", str(path), "--port", port, "--drive", "60", "--arm"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "PYTHONUNBUFFERED": "1"},
    )
    assert cli.stdout is not None
    for line in cli.stdout:
        if seen is not None:
            seen.append(line)
        if "soft_start -> running" in line:
            return cli
    raise AssertionError(f"the CLI never ran: exit {cli.wait(10)}")


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_ctrl_c_of_a_driving_cli_is_an_estop(bus_factory: Callable[..., EmulatedBus], tmp_path: Path, sig: int) -> None:
    path = rig_file(tmp_path)
    rig = load_rig(path)
    emu = bus_factory(servo_setups(rig), baud=rig.bus.baud)
    cli = start_cli(path, emu.port)
    running = len(goal_writes(emu))
    wait_until(lambda: len(goal_writes(emu)) >= running + 20, 10.0, "the CLI stopped writing goals")
    pressed = time.perf_counter()
    cli.send_signal(sig)
    out, _ = cli.communicate(timeout=20)
    assert cli.returncode == EXIT_ESTOP, out
    assert "running -> estop: e-stop (by signal)" in out and "torque off (read back)" in out
    emu.settle()
    off = [t for t, raw in list(emu.arrivals) if is_torque_off_write(raw) and t > pressed]
    assert off and off[0] - pressed < rig.bus.tick_s + 0.001 + 0.02  # one tick + 1 ms (+ signal delivery)
    assert [t for t, _ in goal_writes(emu) if t > off[0]] == []
    assert all(emu.read_item(i, Item.TORQUE_ENABLE) == 0 for i in (1, 2, 3))


def test_a_killed_driver_is_parked_by_its_guardian(bus_factory: Callable[..., EmulatedBus], tmp_path: Path) -> None:
    path = rig_file(tmp_path)
    rig = load_rig(path)
    emu = bus_factory(servo_setups(rig), baud=rig.bus.baud)
    cli = start_cli(path, emu.port)
    running = len(goal_writes(emu))
    wait_until(lambda: len(goal_writes(emu)) >= running + 30, 10.0, "the CLI stopped writing goals")
    killed = time.perf_counter()
    cli.kill()  # SIGKILL: no handler, no goodbye
    cli.communicate(timeout=10)
    torque_on = lambda: any(emu.read_item(i, Item.TORQUE_ENABLE) for i in (1, 2, 3))  # noqa: E731
    wait_until(lambda: not torque_on(), 10.0, "the guardian never turned torque off", poll=0.02)
    writes, off = parked_since(emu, rig, killed)
    assert writes[0] - killed <= 0.2, "the guardian's first park goal within 200 ms"
    assert off[0] - killed <= rig.bus.park_s + 2 * rig.bus.tick_s + 0.2  # the wait for arrival is in park_s
    assert off[0] - killed >= rig.bus.park_ramp_s  # it eased to park first (category 1)


def test_an_orphan_guardian_gives_up_on_a_silent_bus(
    bus_factory: Callable[..., EmulatedBus], tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    """The tick and the web process are gone and no servo answers: the guardian repeats
    torque-off for ``give_up`` seconds, then exits (it never lingers as an orphan)."""
    from riderlive.devices.board import SafetyBoard
    from riderlive.devices.guardian import launch
    from riderlive.devices.latch import StopLatch
    from riderlive.devices.lifecycle import DeviceState
    from riderlive.devices.registry import DeviceSpec
    from riderlive.dynamixel.emulator.faults import parse_fault

    path = rig_file(tmp_path)
    rig = load_rig(path)
    emu = bus_factory(servo_setups(rig), baud=rig.bus.baud)
    latch, board = StopLatch(), SafetyBoard()
    dead = subprocess.Popen(["true"])
    dead.wait()
    board.tick_pid, board.tick_generation = dead.pid, 1
    board.publish(0, DeviceState.DISARMED, [0.0] * len(rig.servos))
    for servo_id in (1, 2, 3):
        emu.apply(parse_fault(f"vanish:{servo_id}"))
    spec = DeviceSpec("dynamixel", str(path), emu.port, rig.name, 1, rig.bus.tick_s)
    started = time.perf_counter()
    guardian = launch(board.name, latch.name, [spec], tick_timeout_s=0.1, web_timeout_s=1.0, give_up_s=1.0)
    try:
        code = guardian.wait(timeout=30)
    finally:
        if guardian.poll() is None:
            guardian.kill()
        board.close()
        latch.close()
    elapsed = time.perf_counter() - started
    err = capfd.readouterr().err
    assert code == 0
    assert re.search(r"outputs-off not confirmed in [\d.]+ s of read-backs; giving up", err), err
    assert 1.0 <= elapsed < 20.0


def watchers(lines: list[str]) -> tuple[int, int]:
    """The guardian and standby pids the CLI said last (``guardian 12 watches; standby 34``)."""
    found = [m for line in lines if (m := re.search(r"guardian (\d+) watches; standby (\d+)", line))]
    assert found, "".join(lines)
    return int(found[-1].group(1)), int(found[-1].group(2))


def all_torque_off(emu: EmulatedBus) -> bool:
    return all(emu.read_item(i, Item.TORQUE_ENABLE) == 0 for i in (1, 2, 3))


def parked_since(emu: EmulatedBus, rig: RigConfig, since: float) -> tuple[list[float], list[float]]:
    """The goal and torque-off writes after ``since`` (perf_counter s), checked as a category 1
    stop: park goals, then torque off with no goal after it, torque read back off on every
    servo, the head at its park pose."""
    emu.settle()
    arrivals = [(t, raw) for t, raw in list(emu.arrivals) if t > since]
    is_goal = [raw[7] == Instruction.SYNC_WRITE and raw[8] == GOAL_POSITION for _, raw in arrivals]
    goals = [t for (t, _), goal in zip(arrivals, is_goal, strict=True) if goal]
    off = [t for t, raw in arrivals if is_torque_off_write(raw)]
    # In arrival order: a starved emulator stamps a whole burst with one time, so times may tie.
    first_off = next((i for i, (_, raw) in enumerate(arrivals) if is_torque_off_write(raw)), len(arrivals))
    assert goals and off and not any(is_goal[first_off:]), "eased to park, then torque off, no goal after"
    assert all_torque_off(emu)
    assert abs(pulses_to_deg(emu.read_item(3, Item.GOAL_POSITION)) - rig.servos["head"].park) < 0.1
    return goals, off


def reap(*pids: int) -> None:
    for pid in pids:
        if pid <= 0:  # kill(0) would be this process group
            continue
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)


@contextlib.contextmanager
def watched_drive(
    bus_factory: Callable[..., EmulatedBus], tmp_path: Path
) -> Iterator[tuple[RigConfig, EmulatedBus, subprocess.Popen[str], list[str]]]:
    """``rig --drive --arm`` as a process on an emulated rig, writing goals (20 more seen), with
    the lines it said so far (its guardian and standby pids among them); afterwards the CLI is
    killed if it still runs and every guardian it named is reaped."""
    path = rig_file(tmp_path)
    rig = load_rig(path)
    emu = bus_factory(servo_setups(rig), baud=rig.bus.baud)
    seen: list[str] = []
    cli = start_cli(path, emu.port, seen)
    try:
        running = len(goal_writes(emu))
        wait_until(lambda: len(goal_writes(emu)) >= running + 20, 10.0, "the CLI stopped writing goals")
        yield rig, emu, cli, seen
    finally:
        if cli.poll() is None:
            cli.kill()
            cli.communicate(timeout=10)
        reap(*{pid for line in seen for pid in map(int, re.findall(r"(?:guardian|standby) (\d+)", line))})


def test_a_killed_guardian_is_replaced_by_its_standby_and_the_tick_parks_the_rig(
    bus_factory: Callable[..., EmulatedBus], tmp_path: Path
) -> None:
    """The service's rule, in ``rig --drive``: the guardian that watched is gone (SIGKILL), its
    standby takes over and a new standby follows (the rig keeps its watch); the tick parks
    the armed rig itself (category 1), the CLI says why and exits 1; torque off, read back."""
    with watched_drive(bus_factory, tmp_path) as (rig, emu, cli, seen):
        guardian, standby = watchers(seen)
        killed = time.perf_counter()
        os.kill(guardian, signal.SIGKILL)
        out, _ = cli.communicate(timeout=30)
        lines = seen + out.splitlines(keepends=True)
        assert cli.returncode == EXIT_FAULT, out
        assert "the tick lost its guardian" in out and "running -> parking" in out, out
        assert re.search(r"running -> parking: disarmed \(by tick: the guardian", out), out
        assert "parking -> parked" in out and "parked by the tick" in out and "closed; fault: none" in out
        now_watching, new_standby = watchers(lines)
        assert now_watching == standby and new_standby not in (0, guardian, standby), "the watch goes on"
        _, off = parked_since(emu, rig, killed)
        assert off[0] - killed >= rig.bus.park_ramp_s  # category 1: a park, not a drop
        wait_until(lambda: not pid_alive(standby) and not pid_alive(new_standby), 10.0, "the guardians stayed")


def test_a_hung_driver_whose_guardian_is_killed_is_parked_by_the_standby(
    bus_factory: Callable[..., EmulatedBus], tmp_path: Path
) -> None:
    """Tick (the CLI, SIGSTOP) and guardian (SIGKILL) both gone: without a standby nobody
    parks (issue 25); with it, the standby becomes the guardian, finds the tick hung, kills
    it and parks the rig from its last published pose; torque off read back."""
    with watched_drive(bus_factory, tmp_path) as (rig, emu, cli, seen):
        guardian, standby = watchers(seen)
        cli.send_signal(signal.SIGSTOP)
        os.kill(guardian, signal.SIGKILL)
        hung = time.perf_counter()
        assert cli.wait(timeout=20) == -signal.SIGKILL, "the standby kills the hung driver"
        wait_until(lambda: all_torque_off(emu), 10.0, "the standby never turned torque off", poll=0.02)
        goals, off = parked_since(emu, rig, hung)
        assert off[0] - goals[0] >= rig.bus.park_ramp_s
        assert goals[0] - hung < 2.0, "the standby's first park goal"
        wait_until(lambda: not pid_alive(standby), 20.0, "the standby stayed after its stop")


def test_a_hung_guardian_and_standby_make_the_tick_park_the_rig(
    bus_factory: Callable[..., EmulatedBus], tmp_path: Path
) -> None:
    """The tick's guardian watch: no guardian beats (both SIGSTOP) -> after GUARDIAN_HANG_S the
    tick parks the rig itself, says why, and the CLI exits 1; torque off read back."""
    with watched_drive(bus_factory, tmp_path) as (rig, emu, cli, seen):
        guardian, standby = watchers(seen)
        os.kill(standby, signal.SIGSTOP)  # first: it would kill a hung guardian and take over
        os.kill(guardian, signal.SIGSTOP)
        stopped = time.perf_counter()
        out, _ = cli.communicate(timeout=40)
        assert cli.returncode == EXIT_FAULT, out
        hung = rf"the tick lost its guardian: the guardian {guardian} has not beaten for \d+ ms \(hung\)"
        assert re.search(hung, out), out
        assert "parking -> parked" in out and "parked by the tick" in out, out
        emu.settle()
        off = [t for t, raw in list(emu.arrivals) if is_torque_off_write(raw) and t > stopped]
        assert off and off[0] - stopped >= GUARDIAN_HANG_S + rig.bus.park_ramp_s
        assert all_torque_off(emu)
