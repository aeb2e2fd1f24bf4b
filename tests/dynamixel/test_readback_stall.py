"""The divided read against the emulated bus on a pty (the real SDK), with the tick's
clock and the host's stall counters scripted: a servo that vanished while the host was
stalled is charged only the time the host ran; a servo that vanished on a running
host faults after exactly the budget, as before."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterator

import pytest

from riderlive.devices.budget import ReplyTimer
from riderlive.devices.lifecycle import NoReply
from riderlive.devices.stall import HostSample
from riderlive.dynamixel.emulator import EmulatedBus
from riderlive.dynamixel.emulator.faults import FaultKind as EmuFault
from riderlive.dynamixel.emulator.faults import FaultSpec
from riderlive.dynamixel.readback import Readback
from riderlive.dynamixel.sdkbus import SdkBus
from tests.dynamixel.rig_harness import servo_setups, short_rig

BUDGET = 0.1


class ScriptedHost:
    """The host's counters as the test says: ``stolen`` seconds of steal on CPU 0 so far."""

    def __init__(self) -> None:
        self.stolen = 0.0
        self.samples = 0

    def sample(self, wall_s: float) -> HostSample:
        self.samples += 1
        return HostSample(wall_s, 0.0, (self.stolen, 0.0))


@pytest.fixture
def setup(bus_factory: Callable[..., EmulatedBus]) -> Iterator[tuple[Readback, SdkBus, EmulatedBus, ScriptedHost]]:
    rig = short_rig("bench3", reply_budget_s=BUDGET, baud=4_000_000)
    emu = bus_factory(servo_setups(rig), baud=4_000_000)
    # replies may wait 200 ms (a loaded 2-core box; the emulator shares this process's GIL):
    # a read of a present servo must not fail here, whatever the load
    bus = SdkBus(emu.port, 4_000_000, 1.0, ReplyTimer(floor_ms=200.0, ceiling_ms=200.0))
    bus.open()
    host = ScriptedHost()
    yield Readback(rig, host), bus, emu, host
    bus.close()


def test_a_host_stall_is_ridden_through_and_the_servo_still_faults_after_the_budget(
    setup: tuple[Readback, SdkBus, EmulatedBus, ScriptedHost],
) -> None:
    rb, bus, emu, host = setup
    counters: Counter[str] = Counter()
    rb.read(bus, set(), 0.0, counters)
    assert counters["reads"] == 1 and host.samples == 0  # nobody silent: the counters are not read
    emu.apply(FaultSpec(EmuFault.VANISH, 2))
    rb.read(bus, set(), 0.01, counters)  # silent since 0.01
    host.stolen = 0.1  # the host stalled 100 ms
    rb.read(bus, set(), 0.12, counters)
    rb.read(bus, set(), 0.20, counters)  # 190 ms on the wall clock, 90 ms of it usable: no fault
    # one count per silent servo (a failed Fast Sync Read, or a plain one that stopped at
    # servo 2, leaves servo 3 unheard too)
    ridden = counters["stall_ridethroughs"]
    assert 1 <= ridden <= 2 and counters["read_failures"] == 3
    with pytest.raises(NoReply) as caught:
        rb.read(bus, set(), 0.21, counters)
    assert caught.value.unit == 2
    assert "no reply for 100 ms of retries, 100 ms more while the host stalled" in str(caught.value)
    assert counters["stall_ridethroughs"] == ridden


def test_a_servo_that_vanished_on_a_running_host_faults_after_the_budget(
    setup: tuple[Readback, SdkBus, EmulatedBus, ScriptedHost],
) -> None:
    rb, bus, emu, _ = setup
    counters: Counter[str] = Counter()
    rb.read(bus, set(), 0.0, counters)
    emu.apply(FaultSpec(EmuFault.VANISH, 3))
    for now in (0.01, 0.05, 0.1):
        rb.read(bus, set(), now, counters)
    with pytest.raises(NoReply) as caught:
        rb.read(bus, set(), 0.11, counters)
    assert caught.value.unit == 3 and "no reply for 100 ms of retries (" in str(caught.value)
    assert counters["stall_ridethroughs"] == 0


def test_an_answer_after_a_stall_ends_the_silence(setup: tuple[Readback, SdkBus, EmulatedBus, ScriptedHost]) -> None:
    rb, bus, emu, host = setup
    counters: Counter[str] = Counter()
    emu.apply(FaultSpec(EmuFault.VANISH, 1))
    rb.read(bus, set(), 0.0, counters)
    host.stolen = 0.5
    rb.read(bus, set(), 0.55, counters)
    emu.apply(FaultSpec(EmuFault.REAPPEAR, 1))
    for k in range(20):  # the first read after it reappears may still catch the line unsettled
        host.stolen += 0.001  # each retry's time is a host stall: no budget is spent meanwhile
        rb.read(bus, set(), 0.56 + 0.001 * k, counters)
        if not rb.silence.silent:
            break
    assert not rb.silence.silent and counters["stall_ridethroughs"] >= 1
    emu.apply(FaultSpec(EmuFault.VANISH, 1))
    rb.read(bus, set(), 0.60, counters)  # a new silence, a new budget
    with pytest.raises(NoReply):
        rb.read(bus, set(), 0.70, counters)
