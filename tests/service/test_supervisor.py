"""The tick supervisor with a real tick process: a setting that stops a tick from
starting makes the next generation start as configured, never a crash loop."""

from __future__ import annotations

import asyncio
import os
import signal
import time
from collections.abc import Callable

import pytest

from riderlive.devices.registry import DeviceSpec
from riderlive.dynamixel.rig import load_rig, longest_tick_wait_s
from riderlive.realtime import commands as cmd
from riderlive.realtime.link import TickLink
from riderlive.rules import load_preset
from riderlive.service.config import ServiceConfig
from riderlive.service.supervisor import TickSupervisor
from riderlive.service.tick_setup import make_setup
from tests.waiting import await_until

CONFIG = ServiceConfig.model_validate({"tick": {"rate": 100.0, "realtime_priority": False, "restart_backoff": 0.05}})


async def _until(condition: Callable[[], bool], timeout: float, what: object) -> None:
    await await_until(condition, timeout, str(what), poll=0.02)


async def _crash_then_start_as_configured() -> None:
    link = TickLink(make_setup(CONFIG, load_preset(CONFIG.tick.preset)))
    dropped: list[int] = []
    supervisor = TickSupervisor(
        link, CONFIG, link.drain_notify, lambda status: None, lambda: dropped.append(link.generation)
    )
    await supervisor.start()
    try:
        await _until(supervisor.ready, 60.0, "the first tick never ticked")
        # What the REST layer refuses (a walk at 4 m/s), kept for the next generation anyway:
        link.apply(cmd.SetGait("walk", 1.5), gait="walk", speed=4.0)
        assert link.base_setup.speed == 4.0
        first_pid = link.process.pid
        assert first_pid is not None
        os.kill(first_pid, signal.SIGKILL)
        # Generation 2 dies at start on the kept walk at 4 m/s; generation 3 ticks as configured.
        await _until(lambda: link.generation >= 3 and supervisor.ready(), 60.0, supervisor.snapshot())
        snapshot = supervisor.snapshot()
        assert (snapshot["deaths"], snapshot["restarts"], snapshot["setups_dropped"]) == (2, 2, 1), snapshot
        assert dropped == [2], "the service is told once, for the generation that failed"
        assert "configured settings" in str(snapshot["last_exit"])
        assert link.base_setup == link.start_setup
        assert (link.setup.gait, link.setup.speed, link.setup.generation) == ("trot", None, 3)
        await _until(lambda: link.status().get("gait") == "trot", 5.0, "the tick reports its gait")
        assert abs(link.status()["speed"] - 3.8) < 1e-9, "the configured trot at its own speed"
        # A second kill with nothing applied since: a plain restart, nothing more dropped.
        os.kill(link.board.tick_pid, signal.SIGKILL)
        await _until(lambda: link.generation >= 4 and supervisor.ready(), 60.0, supervisor.snapshot())
        assert supervisor.snapshot()["setups_dropped"] == 1
    finally:
        await supervisor.stop()
        link.stop(5.0)
        link.close()


def test_the_hang_threshold_waits_out_a_devices_longest_legitimate_wait() -> None:
    """A tick at 500 Hz waiting out one lost servo reply (30 ms for bench3) is not hung:
    the threshold is the hang periods plus that wait (the floors set to 0 to see the sum)."""
    config = ServiceConfig.model_validate(
        {
            "tick": {
                "rate": 500.0,
                "hang_ticks": 5.0,
                "hang_floor": 0.0,
                "hang_floor_realtime": 0.0,
                "hang_floor_cold": 0.0,
            }
        }
    )
    rig = load_rig("bench3")
    spec = DeviceSpec("dynamixel", "bench3", None, rig.name, 1, 0.002, longest_wait_s=longest_tick_wait_s(rig))
    for devices, expected in (((), 4 * 0.002), ((spec,), 4 * 0.002 + longest_tick_wait_s(rig))):
        link = TickLink(make_setup(config, load_preset(config.tick.preset), devices=devices))
        try:
            supervisor = TickSupervisor(link, config, link.drain_notify, lambda status: None)
            supervisor._first_beat = time.perf_counter() - 60.0  # past the start-up grace
            assert supervisor.hang_threshold() == pytest.approx(expected)
        finally:
            link.close()
    assert longest_tick_wait_s(rig) > 0.025, "more than the real-time floor of 30 ms minus the hang periods"


def test_a_setting_that_kills_the_tick_at_start_is_dropped_not_crash_looped() -> None:
    asyncio.run(_crash_then_start_as_configured())


def test_without_a_warm_spare_a_tick_nothing_depends_on_gets_the_cold_floor() -> None:
    """The soak: a 254 ms stall of the tick right after a takeover (its spare still warming)
    was a hang at the 0.25 s floor, and the cold start that followed cost 26.8 s without a
    frame at load 25. With no warm spare and no device moving the threshold is at least
    ``tick.hang_floor_cold``; with a warm spare, or a device moving (the guardian's own
    ``tick_timeout`` watches it then), the usual floor."""
    config = ServiceConfig.model_validate({"tick": {"rate": 120.0, "hang_floor": 0.25, "hang_floor_cold": 2.0}})
    link = TickLink(make_setup(config, load_preset(config.tick.preset)))
    try:
        supervisor = TickSupervisor(link, config, link.drain_notify, lambda status: None)
        supervisor._first_beat = time.perf_counter() - 60.0  # past the start-up grace
        assert link.spare is None and not supervisor.spares.warm()
        assert supervisor.hang_threshold() == pytest.approx(2.0)
        supervisor._a_device_moves = lambda: True  # type: ignore[method-assign]
        assert supervisor.hang_threshold() == pytest.approx(0.25)
        supervisor.spares.warm = lambda: True  # type: ignore[method-assign]
        del supervisor._a_device_moves
        assert supervisor.hang_threshold() == pytest.approx(0.25)  # the floor of a tick not (yet) at SCHED_FIFO
    finally:
        link.close()
