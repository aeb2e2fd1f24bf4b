"""Warm failover with real tick processes: kill -9 or SIGSTOP of the tick, the spare takes
over with the state and the settings, the status tells the truth meanwhile."""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from riderlive.channels import HORSE_NAMES
from riderlive.devices.board import GuardianReport
from riderlive.devices.registry import DeviceSpec
from riderlive.realtime import commands as cmd
from riderlive.realtime.core import Driver
from riderlive.realtime.down import down_status
from riderlive.realtime.link import TickLink
from riderlive.realtime.record import RecordLayout
from riderlive.rules import load_preset
from riderlive.rules.animator import AnimatorLayer
from riderlive.service.config import ServiceConfig
from riderlive.service.supervisor import TickSupervisor
from riderlive.service.tick_setup import make_setup
from tests.waiting import Pacer

RATE = 100.0
CONFIG = ServiceConfig.model_validate({"tick": {"rate": RATE, "realtime_priority": False, "spare_nice": 0}})


class Watch:
    """The link and supervisor with events to await: each tick record, each status published."""

    def __init__(self, config: ServiceConfig = CONFIG) -> None:
        self.link = TickLink(make_setup(config, load_preset(config.tick.preset)))
        self.records: list[tuple[float, np.ndarray]] = []
        self.statuses: list[tuple[bool, dict[str, Any]]] = []
        self.changed = asyncio.Event()
        self.supervisor = TickSupervisor(self.link, config, self.on_tick, self.on_status)

    def on_tick(self) -> None:
        self.link.drain_notify()
        now = time.perf_counter()
        self.records += [(now, r) for r in self.link.read_outputs()]
        self.changed.set()

    def on_status(self, status: dict[str, Any]) -> None:
        self.statuses.append((self.supervisor.up, status))
        self.changed.set()

    async def until(self, condition: Callable[[], bool], timeout: float, what: object) -> None:
        """Await the condition, woken by each record and status (a slow check every 50 ms besides)."""
        deadline = time.perf_counter() + timeout
        while not condition():
            left = deadline - time.perf_counter()
            assert left > 0, what
            self.changed.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self.changed.wait(), min(left, 0.05))

    async def spare_warm(self) -> None:
        await self.until(lambda: self.link.spare is not None and self.link.spare.ready, 300.0, "no warm spare")

    async def close(self) -> None:
        await self.supervisor.stop()
        self.link.stop(5.0)
        self.link.close()


def horse(t: float) -> list[float]:
    values = [0.0] * len(HORSE_NAMES)
    values[HORSE_NAMES.index("rearPivot.rz")] = 4.0 * np.sin(2 * np.pi * 1.5 * t)
    return values


async def _kill_and_take_over() -> None:
    w = Watch()
    await w.supervisor.start()
    feeding = True

    async def producer() -> None:  # a live producer at 100 Hz, its clock 500 s ahead
        pacer = Pacer(0.01)
        while feeding:
            now = w.link.engine_time()
            w.link.push_input(5, 500.0 + now, now, horse(now))
            await pacer.await_next()

    feeder = asyncio.get_running_loop().create_task(producer())
    try:
        await w.until(w.supervisor.ready, 60.0, "the first tick never ticked")
        assert w.supervisor.up and w.statuses[-1][1]["tick_up"] is True
        # Settings applied at run time: a preset's parameters, an animator offset, a gait.
        params = load_preset(CONFIG.tick.preset).model_copy(update={"name": "kept"})
        animator = AnimatorLayer(offsets={"lower_back.rz": 1.5})
        w.link.apply(cmd.SetModel(params, animator), params=params, animator=animator)
        w.link.apply(cmd.SetGait("walk", None), gait="walk", speed=None)
        await w.until(lambda: w.link.status().get("preset") == "kept", 10.0, "the preset applied")
        await w.spare_warm()
        await w.until(lambda: int(w.records[-1][1][RecordLayout.driver.start]) == Driver.INPUT, 10.0, "input drives")
        # the 100 records the slew before the kill is taken from (a loaded -n 2 run had fewer)
        await w.until(lambda: len(w.records) > 100, 30.0, "100 records before the kill")
        spare_pid = w.link.spare.process.pid if w.link.spare else None
        reported = w.link.status()
        before = len(w.records)
        last_seq = float(w.records[-1][1][RecordLayout.seq.start])
        killed_at = time.perf_counter()
        os.kill(w.link.board.tick_pid, signal.SIGKILL)
        await w.until(lambda: w.link.generation == 2 and w.supervisor.up, 30.0, w.supervisor.snapshot())
        await w.until(
            lambda: any(t > killed_at and r[RecordLayout.seq.start] > last_seq for t, r in w.records[before:]), 10.0, ""
        )
        snapshot = w.supervisor.snapshot()
        assert (snapshot["deaths"], snapshot["hangs"], snapshot["restarts"], snapshot["takeovers"]) == (1, 0, 1, 1)
        assert w.link.board.tick_pid == spare_pid, "the warm spare took over"
        # While no generation served, the status said so (and `up` was false).
        down = [(up, s) for up, s in w.statuses if s.get("restarting")]
        assert down and all(not up and s["driver"] == "down" and s["tick_up"] is False for up, s in down)
        # The new generation: the settings, the producer, the seq counting on.
        await w.until(lambda: w.link.status().get("generation") == 2, 10.0, "the new generation's status")
        status = w.link.status()
        assert (status["preset"], status["driver"], status["producer"]) == ("kept", "input", 5)
        assert status["gait"] == reported["gait"], "the procedural horse handed over (its gait change queued)"
        assert w.link.setup.gait == "walk"
        new = [r for t, r in w.records[before:] if t > killed_at]
        seqs = [r[RecordLayout.seq.start] for r in new]
        assert seqs[0] > last_seq and all(b > a for a, b in zip(seqs, seqs[1:])), "seq goes on, increasing"
        gap_ticks = seqs[0] - last_seq
        took = new[0][RecordLayout.engine_t.start] - w.records[before - 1][1][RecordLayout.engine_t.start]
        assert abs(gap_ticks / RATE - took) < 2.5 / RATE, "the same deadline grid"
        assert RecordLayout.driver.count(new[0]) == Driver.INPUT, "the producer kept driving"
        # No jump: the first new frames move no more than the tick moved per tick before the kill.
        rider = np.array([r[RecordLayout.rider.slice] for _, r in w.records[before - 100 : before]])
        slew = np.abs(np.diff(rider, axis=0)).max(axis=0)
        step = np.abs(np.asarray(new[0][RecordLayout.rider.slice]) - rider[-1])
        assert np.all(step <= slew * 1.05 + 1e-9), float((step - slew).max())
        # A new spare warms up in the background.
        await w.spare_warm()
        assert w.link.spare is not None and w.link.spare.process.pid != spare_pid
        # Two deaths in a row: the second with the new spare, the third with none warm (cold).
        os.kill(w.link.board.tick_pid, signal.SIGKILL)
        await w.until(lambda: w.link.generation == 3 and w.supervisor.up, 30.0, w.supervisor.snapshot())
        os.kill(w.link.board.tick_pid, signal.SIGKILL)
        await w.until(lambda: w.link.generation == 4 and w.supervisor.up, 60.0, w.supervisor.snapshot())
        await w.until(lambda: w.link.status().get("generation") == 4, 10.0, "generation 4's status")
        assert w.link.status()["preset"] == "kept", "settings survive a cold start"
        assert (w.link.setup.gait, w.link.setup.animator) == ("walk", animator)
        assert w.supervisor.snapshot()["setups_dropped"] == 0
    finally:
        feeding = False
        await feeder
        await w.close()


@pytest.mark.timeout(900)  # three generations and two spares warmed: minutes on a busy CI host
def test_kill_9_the_spare_takes_over_with_the_state_and_the_settings() -> None:
    asyncio.run(_kill_and_take_over())


async def _stop_and_take_over() -> None:
    w = Watch()
    await w.supervisor.start()
    try:
        await w.until(w.supervisor.ready, 60.0, "the first tick never ticked")
        # A spare killed during its warm-up is replaced (counted), the running tick untouched.
        await w.until(lambda: w.link.spare is not None, 10.0, "a spare is started once the tick beats")
        assert w.link.spare is not None
        first_spare = w.link.spare.process.pid
        assert first_spare is not None
        os.kill(first_spare, signal.SIGKILL)
        await w.spare_warm()
        assert w.link.spare.process.pid != first_spare
        assert (w.link.spares_failed, w.link.generation, w.supervisor.restarts) == (1, 1, 0)
        await w.until(lambda: time.perf_counter() - (w.supervisor._first_beat or 0.0) > 3.5, 10.0, "past warm-up")
        pid = w.link.board.tick_pid
        stopped_at = time.perf_counter()
        os.kill(pid, signal.SIGSTOP)
        await w.until(lambda: w.link.generation == 2 and w.supervisor.up, 30.0, w.supervisor.snapshot())
        snapshot = w.supervisor.snapshot()
        assert (snapshot["hangs"], snapshot["restarts"], snapshot["takeovers"]) == (1, 1, 1), snapshot
        assert "SIGSTOP" in str(snapshot["last_exit"])
        assert snapshot["last_outage"] is not None and time.perf_counter() - stopped_at > snapshot["last_outage"]
        await w.until(lambda: not _alive(pid), 10.0, "the stopped tick was killed")
    finally:
        await w.close()


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().split(b")")[-1].split()[0] != b"Z"
    except OSError:
        return False


@pytest.mark.timeout(600)
def test_sigstop_is_a_hang_and_the_spare_takes_over() -> None:
    asyncio.run(_stop_and_take_over())


async def _down_status_live() -> None:
    w = Watch()
    await w.supervisor.start()
    try:
        await w.until(w.supervisor.ready, 60.0, "the first tick never ticked")
        await w.until(lambda: w.link.status().get("generation") == 1, 10.0, "a status")
        w.link.mark_down("a test")
        status = w.link.status()
        assert (status["driver"], status["tick_up"], status["reason"]) == ("down", False, "a test")
        assert status["preset"] == w.link.setup.params.name, "the settings are still reported"
        w.link.mark_up()
        assert w.link.status()["driver"] != "down"
    finally:
        await w.close()


def test_the_status_of_a_link_marked_down_is_the_down_status() -> None:
    asyncio.run(_down_status_live())


def test_the_down_status_shows_each_device_as_the_guardian_reports_it() -> None:
    specs = [DeviceSpec("dynamixel", f"r{i}.toml", None, f"rig{i}", 1, 0.01) for i in range(4)]
    reports = [GuardianReport.NONE, GuardianReport.PARKING, GuardianReport.OUTPUTS_OFF, GuardianReport.NOT_CONNECTED]
    last = {"driver": "input", "preset": "p", "rig": {"servos": [1]}, "devices": [{"name": "rig0", "state": "running"}]}
    status = down_status(last, specs, reports, estop=False, reason="died (SIGKILL)", generation=3)
    assert [d["state"] for d in status["devices"]] == ["unknown", "parking", "parked", "disconnected"]
    assert [d["outputs_off_confirmed"] for d in status["devices"]] == [False, False, True, False]
    assert status["rig"] is None and status["driver"] == "down" and status["preset"] == "p"
    assert "running" not in str(status["devices"]), "never the dead generation's device state"
