"""The stage dead-man in-process: a virtual clock for the ages, a fake tick for arming state.

The live stage tests (test_stage_safety.py) kill a real broker; these pin the rule itself
and that nothing but cancellation ends the watch."""

from __future__ import annotations

import asyncio
from collections import Counter

import pytest
from hypothesis import given
from hypothesis import strategies as st

from riderlive.bus.stage_deadman import StageDeadMan

TIMEOUT = 0.5


class FakeTick:
    """Armed until a disarm it agrees to; ``refuse`` makes it refuse with that message."""

    def __init__(self, armed: bool = True, refuse: str | None = None) -> None:
        self.is_armed, self.refuse = armed, refuse
        self.disarms: list[str] = []
        self.estops = 0
        self.disarmed = asyncio.Event()

    def armed(self) -> bool:
        return self.is_armed

    async def disarm(self, by: str) -> str | None:
        self.disarms.append(by)
        self.disarmed.set()
        if self.refuse is None:
            self.is_armed = False
        return self.refuse

    def estop(self) -> None:
        self.estops += 1
        self.is_armed = False


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def dead_man(tick: FakeTick, clock: Clock, timeout: float = TIMEOUT) -> StageDeadMan:
    return StageDeadMan(
        timeout, "S", armed=tick.armed, disarm=tick.disarm, estop=tick.estop, counts=Counter(), clock=clock
    )


def test_a_missed_heartbeat_disarms_once_past_the_timeout_and_nothing_rearms() -> None:
    tick, clock = FakeTick(), Clock()
    watch = dead_man(tick, clock)
    watch.beat()
    clock.now += TIMEOUT  # exactly the timeout: not yet lost
    asyncio.run(watch.look())
    assert tick.disarms == [] and not watch.lost
    clock.now += 0.01
    asyncio.run(watch.look())
    assert tick.disarms == ["stage heartbeat lost (0.51 s)"] and watch.lost and not tick.is_armed
    assert watch.counts == Counter(heartbeat_lost=1, heartbeat_stops=1)
    asyncio.run(watch.look())  # lost and disarmed: nothing more to stop
    assert len(tick.disarms) == 1
    watch.beat()
    asyncio.run(watch.look())
    assert not watch.lost and watch.counts["heartbeat_back"] == 1 and not tick.is_armed  # nothing re-arms


def test_arming_waits_for_a_heartbeat() -> None:
    tick, clock = FakeTick(armed=False), Clock()
    watch = dead_man(tick, clock)
    refusal = watch.arm_refusal()
    assert refusal is not None and "no stage heartbeat within 0.5 s on stage 'S'" in refusal
    watch.beat()
    clock.now += TIMEOUT
    assert watch.arm_refusal() is None
    clock.now += 0.01
    assert watch.arm_refusal() is not None


def test_a_refused_stop_of_an_armed_rig_is_an_estop() -> None:
    tick, clock = FakeTick(refuse="the tick is restarting"), Clock()
    watch = dead_man(tick, clock)
    clock.now += 1.0  # never a heartbeat: the age counts from joining
    asyncio.run(watch.look())
    assert tick.estops == 1 and not tick.is_armed


def test_a_refused_stop_of_a_rig_no_longer_armed_is_not_an_estop() -> None:
    tick, clock = FakeTick(refuse="nothing to disarm"), Clock()

    async def refuse_after_parking(by: str) -> str | None:
        tick.is_armed = False  # parked meanwhile (by the guardian, an operator)
        return "nothing to disarm"

    watch = StageDeadMan(
        TIMEOUT, "S", armed=tick.armed, disarm=refuse_after_parking, estop=tick.estop, counts=Counter(), clock=clock
    )
    clock.now += 1.0
    asyncio.run(watch.look())
    assert tick.estops == 0


def test_a_look_that_raises_is_counted_and_the_watch_goes_on(caplog: pytest.LogCaptureFixture) -> None:
    """Only cancellation ends the watch: the first look raises, a later one stops the rig."""
    tick = FakeTick()
    failures = [RuntimeError("a status nobody could parse")]

    def armed() -> bool:
        if failures:
            raise failures.pop()
        return tick.armed()

    watch = StageDeadMan(0.05, "S", armed=armed, disarm=tick.disarm, estop=tick.estop, counts=Counter())

    async def scenario() -> None:
        task = asyncio.create_task(watch.run())
        await asyncio.wait_for(tick.disarmed.wait(), 5.0)
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task

    asyncio.run(scenario())
    assert watch.counts["deadman_errors"] == 1 and not tick.is_armed
    assert "a status nobody could parse" in caplog.text


def test_a_zero_timeout_turns_it_off() -> None:
    tick, clock = FakeTick(), Clock()
    watch = dead_man(tick, clock, timeout=0.0)
    assert watch.arm_refusal() is None
    asyncio.run(asyncio.wait_for(watch.run(), 1.0))  # returns at once
    assert tick.disarms == []


@given(
    beats=st.lists(st.floats(0.0, 10.0), max_size=8),
    look=st.floats(0.0, 20.0),
    timeout=st.floats(0.01, 5.0),
)
def test_lost_is_exactly_an_age_past_the_timeout(beats: list[float], look: float, timeout: float) -> None:
    tick, clock = FakeTick(armed=False), Clock()
    watch = dead_man(tick, clock, timeout)
    start = clock.now
    for t in sorted(beats):
        clock.now = start + t
        watch.beat()
    clock.now = max(clock.now, start + look)
    asyncio.run(watch.look())
    last = start + max(beats) if beats else start
    assert watch.lost == (clock.now - last > timeout)
    assert (watch.arm_refusal() is not None) == (not beats or clock.now - last > timeout)
