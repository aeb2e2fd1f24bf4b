"""Fault injection, seen through the unmodified SDK; the Bus Watchdog; the fault grammar."""

from __future__ import annotations

import os
import random
import termios
import time
from collections.abc import Callable

import pytest
from dynamixel_sdk import COMM_PORT_BUSY, COMM_RX_CORRUPT, COMM_RX_TIMEOUT, COMM_SUCCESS, GroupSyncRead

from riderlive.dynamixel.emulator import EmulatedBus
from riderlive.dynamixel.emulator.faults import FaultKind, FaultSpec, parse_fault
from riderlive.dynamixel.tables import ALERT_BIT, HardwareError, Item, StatusError

from ..conftest import ManualClock, SdkLink

PRESENT = 132


def sync_reader(link: SdkLink, ids: tuple[int, ...] = (1, 2, 3)) -> GroupSyncRead:
    reader = GroupSyncRead(link.port, link.ph, PRESENT, 4)
    for i in ids:
        reader.addParam(i)
    return reader


def test_drop_a_count_of_replies(bus: EmulatedBus, sdk: SdkLink) -> None:
    bus.apply(parse_fault("drop:2:2"))
    results = [sdk.ph.ping(sdk.port, 2)[1] for _ in range(3)]
    assert results == [COMM_RX_TIMEOUT, COMM_RX_TIMEOUT, COMM_SUCCESS]
    assert sdk.ph.ping(sdk.port, 1)[1] == COMM_SUCCESS  # other servos unaffected
    assert bus.stats.dropped_replies == 2


def test_drop_with_a_seeded_probability_is_reproducible(bus: EmulatedBus, sdk: SdkLink) -> None:
    bus.apply(parse_fault("drop:3:0.25:11"))
    rng = random.Random(11)
    expected = [COMM_RX_TIMEOUT if rng.random() < 0.25 else COMM_SUCCESS for _ in range(12)]
    assert [sdk.ph.ping(sdk.port, 3)[1] for _ in range(12)] == expected
    assert COMM_RX_TIMEOUT in expected and COMM_SUCCESS in expected


def test_corrupt_replies_fail_the_crc(bus: EmulatedBus, sdk: SdkLink) -> None:
    bus.apply(parse_fault("corrupt:1:1"))
    assert sdk.ph.ping(sdk.port, 1)[1] == COMM_RX_CORRUPT
    assert sdk.ph.ping(sdk.port, 1) == (1060, COMM_SUCCESS, 0)
    # A corrupted link in a Fast Sync Read chain spoils the whole packet (one CRC at the end).
    bus.apply(parse_fault("corrupt:2:1"))
    reader = sync_reader(sdk)
    assert reader.fastSyncRead() == COMM_RX_CORRUPT
    assert reader.fastSyncRead() == COMM_SUCCESS
    assert bus.stats.corrupted_replies == 2


def test_a_lagged_reply_reaches_the_host_late_and_whole(bus: EmulatedBus, sdk: SdkLink) -> None:
    """``lag:2:80``: the next reply of servo 2 comes a byte at a time over 80 ms; a host
    that waits long enough gets it intact."""
    bus.apply(parse_fault("lag:2:80"))
    start = time.perf_counter()
    _, result, _ = sdk.ph.ping(sdk.port, 2)
    took = time.perf_counter() - start
    assert result == COMM_SUCCESS and took >= 0.075, took
    assert bus.stats.lagged_replies == 1
    assert sdk.ph.ping(sdk.port, 2)[1] == COMM_SUCCESS, "one reply only"
    with pytest.raises(ValueError, match="lag needs a length"):
        parse_fault("lag:2")
    assert parse_fault("lag:3:12.5") == FaultSpec(FaultKind.LAG, 3, 1, None, 0, 0.0, None, 12.5)


def test_clear_removes_reply_faults(bus: EmulatedBus, sdk: SdkLink) -> None:
    bus.apply(parse_fault("drop:1:100"))
    bus.apply(parse_fault("clear"))
    assert sdk.ph.ping(sdk.port, 1)[1] == COMM_SUCCESS


def test_a_vanished_servo_breaks_reads_and_comes_back(bus: EmulatedBus, sdk: SdkLink) -> None:
    bus.apply(parse_fault("vanish:2"))
    assert sdk.ph.ping(sdk.port, 2)[1] == COMM_RX_TIMEOUT
    reader = sync_reader(sdk)
    # A plain Sync Read still gets the others' replies (GroupSyncRead stops at the missing one).
    assert reader.txRxPacket() == COMM_RX_TIMEOUT
    assert reader.txPacket() == COMM_SUCCESS
    results = [sdk.ph.readRx(sdk.port, i, 4)[1] for i in (1, 3, 2)]
    assert results == [COMM_SUCCESS, COMM_SUCCESS, COMM_RX_TIMEOUT]
    # Fast Sync Read is one chained packet: servo 3 cannot continue it, so it is truncated.
    assert reader.fastSyncRead() in (COMM_RX_CORRUPT, COMM_RX_TIMEOUT)
    bus.apply(parse_fault("reappear:2"))
    assert reader.fastSyncRead() == COMM_SUCCESS
    assert [reader.getData(i, PRESENT, 4) for i in (1, 2, 3)] == [2048, 2048, 2048]


def test_overheating_and_overload_shut_the_servo_down(bus: EmulatedBus, sdk: SdkLink) -> None:
    for servo_id in (1, 3):
        assert sdk.ph.write1ByteTxRx(sdk.port, servo_id, 64, 1) == (COMM_SUCCESS, 0)
    bus.apply(parse_fault("overheat:1"))
    bus.apply(parse_fault("overload:3"))
    temperature, result, error = sdk.ph.read1ByteTxRx(sdk.port, 1, 146)
    assert (result, error) == (COMM_SUCCESS, ALERT_BIT)
    assert temperature > bus.read_item(1, Item.TEMPERATURE_LIMIT)
    assert sdk.ph.read1ByteTxRx(sdk.port, 1, 70)[0] == HardwareError.OVERHEATING
    assert sdk.ph.read1ByteTxRx(sdk.port, 3, 70)[0] == HardwareError.OVERLOAD
    assert [sdk.ph.read1ByteTxRx(sdk.port, i, 64)[0] for i in (1, 3)] == [0, 0]
    # The Alert bit rides on every status of that servo, including sync read replies.
    assert sync_reader(sdk).txPacket() == COMM_SUCCESS
    assert [sdk.ph.readRx(sdk.port, i, 4)[2] for i in (1, 2, 3)] == [ALERT_BIT, 0, ALERT_BIT]


def test_sustained_effort_heats_the_servo_until_it_shuts_down(
    timed_bus: EmulatedBus, timed_sdk: SdkLink, clock: ManualClock
) -> None:
    ph, port = timed_sdk.ph, timed_sdk.port
    assert ph.write1ByteTxRx(port, 2, 64, 1) == (COMM_SUCCESS, 0)
    with timed_bus.lock:
        servo = timed_bus.servo(2)
        servo.external_load = 1.0  # something blocks the horn: full effort
    clock.advance(60.0)  # half the 120 s time constant: 25 + 80 (1 - e^-0.5) = 56.5 deg C
    assert ph.read1ByteTxRx(port, 2, 146) == (56, COMM_SUCCESS, 0)
    clock.advance(120.0)  # it crosses the XM430's 80 deg C limit: Overheating, torque off
    assert ph.read1ByteTxRx(port, 2, 70) == (HardwareError.OVERHEATING, COMM_SUCCESS, ALERT_BIT)
    assert ph.read1ByteTxRx(port, 2, 64)[0] == 0
    clock.advance(600.0)  # and cools back toward 25 deg C
    assert ph.read1ByteTxRx(port, 2, 146)[0] < 30


def test_the_port_vanishing(bus: EmulatedBus, sdk: SdkLink) -> None:
    assert sdk.ph.ping(sdk.port, 1)[1] == COMM_SUCCESS
    bus.apply(parse_fault("close"))
    assert not os.path.exists(bus.port)
    # The SDK's next call raises (its clearPort flushes a tty that is gone), and it leaves its
    # port marked in use, so every later call reports COMM_PORT_BUSY: reopen to recover.
    with pytest.raises(termios.error):
        sdk.ph.ping(sdk.port, 1)
    assert sdk.ph.ping(sdk.port, 1)[1] == COMM_PORT_BUSY


def test_bus_watchdog_stops_the_servo_and_locks_goals(
    timed_bus: EmulatedBus, timed_sdk: SdkLink, clock: ManualClock
) -> None:
    bus, ph, port = timed_bus, timed_sdk.ph, timed_sdk.port
    assert ph.write4ByteTxRx(port, 1, 112, 30) == (COMM_SUCCESS, 0)  # 468.9 pulse/s
    assert ph.write1ByteTxRx(port, 1, 64, 1) == (COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 1, 98, 2) == (COMM_SUCCESS, 0)  # 40 ms
    assert ph.write4ByteTxRx(port, 1, 116, 4000) == (COMM_SUCCESS, 0)
    # Fed every 30 ms, the watchdog holds and the servo keeps moving.
    for _ in range(10):
        clock.advance(0.030)
        assert ph.read1ByteTxRx(port, 1, 98) == (2, COMM_SUCCESS, 0)
    assert bus.position(1) == pytest.approx(2048 + 468.9 * 0.300, abs=1.0)
    clock.advance(0.100)  # silence: the watchdog expires 40 ms after the last packet
    value, result, error = ph.read1ByteTxRx(port, 1, 98)
    assert (value, result, error) == (0xFF, COMM_SUCCESS, 0)  # -1: Bus Watchdog Error
    stopped = bus.position(1)
    assert stopped == pytest.approx(2048 + 468.9 * 0.340, abs=1.0)
    assert ph.read1ByteTxRx(port, 1, 64)[0] == 1  # torque stays on, holding
    assert ph.write4ByteTxRx(port, 1, 116, 3000) == (COMM_SUCCESS, StatusError.DATA_RANGE)
    assert ph.write1ByteTxRx(port, 1, 98, 5) == (COMM_SUCCESS, StatusError.DATA_RANGE)
    clock.advance(0.100)
    assert bus.position(1) == stopped
    assert ph.write1ByteTxRx(port, 1, 98, 0) == (COMM_SUCCESS, 0)  # clears the error
    assert ph.write4ByteTxRx(port, 1, 116, 3000) == (COMM_SUCCESS, 0)
    clock.advance(0.100)
    assert bus.position(1) == pytest.approx(stopped + 468.9 * 0.100, abs=1.0)  # moving again, toward 3000


def test_the_watchdog_trips_at_its_deadline_not_at_the_next_packet(
    timed_bus: EmulatedBus, timed_sdk: SdkLink, clock: ManualClock
) -> None:
    ph, port = timed_sdk.ph, timed_sdk.port
    assert ph.write1ByteTxRx(port, 3, 64, 1) == (COMM_SUCCESS, 0)
    assert ph.write4ByteTxRx(port, 3, 112, 20) == (COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 3, 98, 1) == (COMM_SUCCESS, 0)  # 20 ms
    assert ph.write4ByteTxRx(port, 3, 116, 3000) == (COMM_SUCCESS, 0)
    clock.advance(0.150)
    # 20 x 0.229 rev/min = 312.6 pulse/s, for the 20 ms before the trip, not the 150 ms of silence.
    assert timed_bus.position(3) - 2048 == pytest.approx(312.6 * 0.020, abs=1.0)


def test_a_vanished_servo_stops_by_its_watchdog(timed_bus: EmulatedBus, timed_sdk: SdkLink, clock: ManualClock) -> None:
    ph, port = timed_sdk.ph, timed_sdk.port
    assert ph.write1ByteTxRx(port, 2, 64, 1) == (COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 2, 98, 1) == (COMM_SUCCESS, 0)
    timed_bus.apply(parse_fault("vanish:2"))  # the cable to servo 2 is cut
    for _ in range(5):
        clock.advance(0.010)
        assert ph.ping(port, 1)[1] == COMM_SUCCESS  # traffic for others does not reach servo 2
    assert timed_bus.read_item(2, Item.BUS_WATCHDOG) == -1
    assert timed_bus.read_item(1, Item.BUS_WATCHDOG) == 0


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("drop:3:5", FaultSpec(FaultKind.DROP, 3, count=5)),
        ("drop:3", FaultSpec(FaultKind.DROP, 3, count=1)),
        ("drop:3:0.1:7", FaultSpec(FaultKind.DROP, 3, probability=0.1, seed=7)),
        ("corrupt:12:2@1.5", FaultSpec(FaultKind.CORRUPT, 12, count=2, at_s=1.5)),
        ("vanish:7@10", FaultSpec(FaultKind.VANISH, 7, at_s=10.0)),
        ("OVERHEAT:1", FaultSpec(FaultKind.OVERHEAT, 1)),
        ("close@20", FaultSpec(FaultKind.CLOSE, at_s=20.0)),
        ("clear", FaultSpec(FaultKind.CLEAR)),
    ],
)
def test_parse_fault(text: str, expected: FaultSpec) -> None:
    assert parse_fault(text) == expected


@pytest.mark.parametrize("text", ["", "explode:1", "drop", "drop:x", "drop:1:1.5", "vanish:1@-1", "drop:1:2:3:4"])
def test_parse_fault_rejects(text: str) -> None:
    with pytest.raises(ValueError, match="fault"):
        parse_fault(text)


def test_faults_apply_to_servos_by_their_current_id(bus_factory: Callable[..., EmulatedBus]) -> None:
    bus = bus_factory()
    with pytest.raises(KeyError):
        bus.apply(parse_fault("overload:9"))
