"""The unmodified dynamixel-sdk against the emulated bus over a pty: every instruction."""

from __future__ import annotations

import time

from dynamixel_sdk import (
    COMM_RX_TIMEOUT,
    COMM_SUCCESS,
    GroupBulkRead,
    GroupBulkWrite,
    GroupSyncRead,
    GroupSyncWrite,
)

from riderlive.dynamixel.emulator import EmulatedBus, ServoSetup
from riderlive.dynamixel.emulator.protocol import PacketReader, decode_status, encode_instruction, encode_status
from riderlive.dynamixel.tables import ALERT_BIT, HardwareError, Instruction, Item, StatusError
from tests.waiting import wait_until

from ..conftest import SdkLink, open_sdk

GOAL, PRESENT = 116, 132


def exchange(bus: EmulatedBus, link: SdkLink, packet: bytes, timeout: float = 2.0) -> list[bytes]:
    """Write raw bytes on the SDK's port; return every packet the bus sent back for them.

    Awaits the events, not the clock: the bus has handled the instruction (its packet count,
    then its lock: a packet's replies are all written before the lock is let go), then the
    host has read every byte the bus wrote meanwhile."""
    link.port.clearPort()
    with bus.lock:
        packets, sent = bus.stats.packets, bus.stats.bytes_out
    link.port.writePort(packet)
    wait_until(lambda: bus.stats.packets > packets, timeout, "the bus handled the instruction")
    with bus.lock:
        expected = bus.stats.bytes_out - sent
    raw = bytearray()

    def arrived() -> bool:
        raw.extend(link.port.readPort(1024))
        return len(raw) >= expected

    wait_until(arrived, timeout, lambda: f"{len(raw)} of the {expected} bytes the bus wrote")
    reader = PacketReader()
    reader.feed(bytes(raw))
    return [p for p in reader.packets() if isinstance(p, bytes)]


def s32(value: int) -> int:
    return value - (1 << 32) if value & 0x80000000 else value


def test_ping_is_byte_exact_both_ways(bus: EmulatedBus, sdk: SdkLink) -> None:
    assert sdk.ph.ping(sdk.port, 1) == (1060, COMM_SUCCESS, 0)
    assert bus.received[-1].hex(" ") == "ff ff fd 00 01 03 00 01 19 4e"
    # The e-manual's example reply: an XM430-W210 (model 1030) with firmware 38.
    bus.write_item(1, Item.MODEL_NUMBER, 1030)
    bus.write_item(1, Item.FIRMWARE_VERSION, 38)
    replies = exchange(bus, sdk, bytes.fromhex("ff ff fd 00 01 03 00 01 19 4e"))
    assert [r.hex(" ") for r in replies] == ["ff ff fd 00 01 07 00 55 00 06 04 26 65 5d"]


def test_ping_reports_each_model(sdk: SdkLink) -> None:
    assert [sdk.ph.ping(sdk.port, i)[0] for i in (1, 2, 3)] == [1060, 1020, 1200]


def test_broadcast_ping_answers_in_id_order(bus: EmulatedBus, sdk: SdkLink) -> None:
    replies = exchange(bus, sdk, encode_instruction(0xFE, Instruction.PING))
    assert [decode_status(r).id for r in replies] == [1, 2, 3]
    found, result = sdk.ph.broadcastPing(sdk.port)
    assert result == COMM_SUCCESS
    assert {i: v[0] for i, v in found.items()} == {1: 1060, 2: 1020, 3: 1200}


def test_read_write_round_trip_and_motion(bus: EmulatedBus, sdk: SdkLink) -> None:
    assert sdk.ph.write1ByteTxRx(sdk.port, 1, 64, 1) == (COMM_SUCCESS, 0)
    assert sdk.ph.write4ByteTxRx(sdk.port, 1, GOAL, 2300) == (COMM_SUCCESS, 0)
    assert sdk.ph.read4ByteTxRx(sdk.port, 1, GOAL) == (2300, COMM_SUCCESS, 0)
    wait_until(lambda: sdk.ph.read4ByteTxRx(sdk.port, 1, PRESENT)[0] == 2300, 1.0, "it never got there")
    assert sdk.ph.read4ByteTxRx(sdk.port, 1, PRESENT) == (2300, COMM_SUCCESS, 0)
    assert sdk.ph.read1ByteTxRx(sdk.port, 1, 122)[0] == 0  # Moving


def test_eeprom_is_locked_while_torque_is_on(sdk: SdkLink) -> None:
    assert sdk.ph.write1ByteTxRx(sdk.port, 2, 9, 0) == (COMM_SUCCESS, 0)  # Return Delay Time
    assert sdk.ph.write1ByteTxRx(sdk.port, 2, 64, 1) == (COMM_SUCCESS, 0)
    assert sdk.ph.write1ByteTxRx(sdk.port, 2, 9, 10) == (COMM_SUCCESS, StatusError.ACCESS)
    assert sdk.ph.write4ByteTxRx(sdk.port, 2, 48, 3000) == (COMM_SUCCESS, StatusError.ACCESS)
    assert sdk.ph.read1ByteTxRx(sdk.port, 2, 9)[0] == 0  # unchanged
    assert sdk.ph.write1ByteTxRx(sdk.port, 2, 64, 0) == (COMM_SUCCESS, 0)
    assert sdk.ph.write1ByteTxRx(sdk.port, 2, 9, 10) == (COMM_SUCCESS, 0)


def test_access_length_range_and_limit_errors(sdk: SdkLink) -> None:
    ph, port = sdk.ph, sdk.port
    assert ph.write4ByteTxRx(port, 1, PRESENT, 5)[1] == StatusError.ACCESS  # read-only
    assert ph.write2ByteTxRx(port, 1, 0, 7)[1] == StatusError.ACCESS  # Model Number
    assert ph.write1ByteTxRx(port, 1, 14, 1)[1] == StatusError.ACCESS  # a gap between items
    assert ph.write2ByteTxRx(port, 1, GOAL, 100)[1] == StatusError.DATA_LENGTH  # half an item
    assert ph.write1ByteTxRx(port, 1, 11, 2)[1] == StatusError.DATA_RANGE  # no Operating Mode 2
    assert ph.write1ByteTxRx(port, 1, 9, 255)[1] == StatusError.DATA_RANGE  # Return Delay 0..254
    assert ph.write4ByteTxRx(port, 1, 48, 3000) == (COMM_SUCCESS, 0)  # Max Position Limit
    assert ph.write4ByteTxRx(port, 1, GOAL, 3001)[1] == StatusError.DATA_LIMIT
    assert ph.write4ByteTxRx(port, 1, GOAL, 3000) == (COMM_SUCCESS, 0)
    assert ph.write4ByteTxRx(port, 1, 112, 40_000)[1] == StatusError.DATA_RANGE  # Profile Velocity
    assert ph.readTxRx(port, 1, 600, 100)[2] == StatusError.ACCESS  # beyond the XL430 table
    # Extended Position Control Mode accepts multi-turn goals; the position limits no longer apply.
    assert ph.write1ByteTxRx(port, 1, 11, 4) == (COMM_SUCCESS, 0)
    assert ph.write4ByteTxRx(port, 1, GOAL, 10_000) == (COMM_SUCCESS, 0)
    assert ph.write4ByteTxRx(port, 1, GOAL, 2_000_000)[1] == StatusError.DATA_RANGE


def test_a_refused_multi_item_write_changes_nothing(bus: EmulatedBus, sdk: SdkLink) -> None:
    # Profile Acceleration, Profile Velocity, Goal Position in one write; the velocity is out of range.
    data = (100).to_bytes(4, "little") + (40_000).to_bytes(4, "little") + (1000).to_bytes(4, "little")
    assert sdk.ph.writeTxRx(sdk.port, 3, 108, 12, list(data))[1] == StatusError.DATA_RANGE
    assert bus.read_item(3, Item.PROFILE_ACCELERATION) == 0
    data = (100).to_bytes(4, "little") + (200).to_bytes(4, "little") + (1000).to_bytes(4, "little")
    assert sdk.ph.writeTxRx(sdk.port, 3, 108, 12, list(data)) == (COMM_SUCCESS, 0)
    assert [bus.read_item(3, i) for i in (Item.PROFILE_ACCELERATION, Item.PROFILE_VELOCITY, Item.GOAL_POSITION)] == [
        100,
        200,
        1000,
    ]


def test_byte_stuffing_through_the_sdk(bus: EmulatedBus, sdk: SdkLink) -> None:
    value = int.from_bytes(b"\xff\xff\xfd\xff", "little", signed=True)  # -131073, a valid Homing Offset
    # dynamixel-sdk 4.1's txPacket drops the result of addStuffing, so it sends FF FF FD unstuffed;
    # the length-framed packet still parses (nothing to remove: FD is not followed by FD).
    assert sdk.ph.write4ByteTxRx(sdk.port, 1, 20, value & 0xFFFFFFFF) == (COMM_SUCCESS, 0)
    assert bus.read_item(1, Item.HOMING_OFFSET) == value
    # A correctly stuffed instruction (our encoder) is unstuffed by the emulator.
    bus.write_item(1, Item.HOMING_OFFSET, 0)
    packet = encode_instruction(1, Instruction.WRITE, bytes((20, 0)) + b"\xff\xff\xfd\xff")
    assert b"\xff\xff\xfd\xfd" in packet
    (reply,) = exchange(bus, sdk, packet)
    assert decode_status(reply).error == 0
    assert bus.read_item(1, Item.HOMING_OFFSET) == value
    # The emulator stuffs its reply; the SDK unstuffs it.
    (reply,) = exchange(bus, sdk, encode_instruction(1, Instruction.READ, bytes((20, 0, 4, 0))))
    assert b"\xff\xff\xfd\xfd" in reply
    read, result, _ = sdk.ph.read4ByteTxRx(sdk.port, 1, 20)
    assert (result, s32(read)) == (COMM_SUCCESS, value)


def test_reg_write_waits_for_action(bus: EmulatedBus, sdk: SdkLink) -> None:
    assert sdk.ph.regWriteTxRx(sdk.port, 2, 65, 1, [1]) == (COMM_SUCCESS, 0)  # LED
    assert sdk.ph.read1ByteTxRx(sdk.port, 2, 69)[0] == 1  # Registered Instruction
    assert sdk.ph.read1ByteTxRx(sdk.port, 2, 65)[0] == 0
    assert sdk.ph.action(sdk.port, 0xFE) == COMM_SUCCESS
    bus.settle()
    assert sdk.ph.read1ByteTxRx(sdk.port, 2, 65)[0] == 1
    assert sdk.ph.read1ByteTxRx(sdk.port, 2, 69)[0] == 0
    # ACTION with nothing registered is an Instruction error.
    (reply,) = exchange(bus, sdk, encode_instruction(2, Instruction.ACTION))
    assert decode_status(reply).error == StatusError.INSTRUCTION


def test_unknown_instruction_and_bad_crc(bus: EmulatedBus, sdk: SdkLink) -> None:
    (reply,) = exchange(bus, sdk, encode_instruction(1, 0x77))
    assert decode_status(reply).error == StatusError.INSTRUCTION
    bad = bytearray(encode_instruction(1, Instruction.PING))
    bad[-1] ^= 0x55
    (reply,) = exchange(bus, sdk, bytes(bad))
    assert decode_status(reply) == decode_status(encode_status(1, StatusError.CRC))
    # Line noise before a packet is skipped.
    (reply,) = exchange(bus, sdk, b"\x00\xff\x13" + encode_instruction(3, Instruction.PING))
    assert decode_status(reply).id == 3


def test_reboot_restores_ram_defaults_and_keeps_eeprom(bus: EmulatedBus, sdk: SdkLink) -> None:
    assert sdk.ph.write1ByteTxRx(sdk.port, 1, 9, 0) == (COMM_SUCCESS, 0)  # EEPROM
    assert sdk.ph.write1ByteTxRx(sdk.port, 1, 65, 1) == (COMM_SUCCESS, 0)  # RAM
    assert sdk.ph.write1ByteTxRx(sdk.port, 1, 64, 1) == (COMM_SUCCESS, 0)
    assert sdk.ph.reboot(sdk.port, 1) == (COMM_SUCCESS, 0)
    assert [sdk.ph.read1ByteTxRx(sdk.port, 1, a)[0] for a in (9, 65, 64)] == [0, 0, 0]


def test_factory_reset_options(bus: EmulatedBus, sdk: SdkLink) -> None:
    assert sdk.ph.write1ByteTxRx(sdk.port, 2, 9, 0) == (COMM_SUCCESS, 0)
    assert sdk.ph.factoryReset(sdk.port, 2, 0x02) == (COMM_SUCCESS, 0)  # keep ID and baud
    assert sdk.ph.read1ByteTxRx(sdk.port, 2, 9) == (250, COMM_SUCCESS, 0)
    # A full reset also restores ID 1 and 57600 bit/s: the servo leaves this 4 Mbit/s bus.
    assert sdk.ph.factoryReset(sdk.port, 2, 0xFF) == (COMM_SUCCESS, 0)
    assert sdk.ph.ping(sdk.port, 2)[1] == COMM_RX_TIMEOUT
    with bus.lock:
        ids = sorted(s.id for s in bus.servos)
        bauds = [s.get(Item.BAUD_RATE) for s in bus.servos]
    assert ids == [1, 1, 3]
    assert bauds == [6, 1, 6]


def test_status_return_level(bus: EmulatedBus, sdk: SdkLink) -> None:
    assert sdk.ph.write1ByteTxRx(sdk.port, 3, 68, 1) == (COMM_SUCCESS, 0)
    assert sdk.ph.read1ByteTxRx(sdk.port, 3, 68) == (1, COMM_SUCCESS, 0)
    assert exchange(bus, sdk, encode_instruction(3, Instruction.WRITE, bytes((65, 0, 1)))) == []
    assert sdk.ph.ping(sdk.port, 3)[1] == COMM_SUCCESS


def test_sync_write_and_sync_read(bus: EmulatedBus, sdk: SdkLink) -> None:
    writer = GroupSyncWrite(sdk.port, sdk.ph, 108, 12)  # acceleration, velocity, goal
    for i, goal in ((1, 2100), (2, 1900), (3, 2050)):
        assert writer.addParam(i, list((0).to_bytes(8, "little") + goal.to_bytes(4, "little")))
    assert sdk.ph.write1ByteTxRx(sdk.port, 0xFE, 64, 1)[0] == COMM_SUCCESS  # broadcast write
    assert writer.txPacket() == COMM_SUCCESS
    bus.settle()
    assert bus.stats.instructions["SYNC_WRITE"] == 1
    reader = GroupSyncRead(sdk.port, sdk.ph, GOAL, 4)
    for i in (1, 2, 3):
        reader.addParam(i)
    assert reader.txRxPacket() == COMM_SUCCESS
    assert [reader.getData(i, GOAL, 4) for i in (1, 2, 3)] == [2100, 1900, 2050]
    positions = lambda: [bus.read_item(i, Item.PRESENT_POSITION) for i in (1, 2, 3)]  # noqa: E731 - off the wire
    wait_until(lambda: positions() == [2100, 1900, 2050], 5.0, positions, poll=0.02)  # moving in emulated time
    assert reader.fastSyncRead() == COMM_SUCCESS
    present = GroupSyncRead(sdk.port, sdk.ph, PRESENT, 4)
    for i in (1, 2, 3):
        present.addParam(i)
    assert present.fastSyncRead() == COMM_SUCCESS
    assert [present.getData(i, PRESENT, 4) for i in (1, 2, 3)] == [2100, 1900, 2050]
    assert bus.stats.instructions["FAST_SYNC_READ"] == 2


def test_bulk_write_and_bulk_read(bus: EmulatedBus, sdk: SdkLink) -> None:
    writer = GroupBulkWrite(sdk.port, sdk.ph)
    assert writer.addParam(1, 65, 1, [1])  # LED
    assert writer.addParam(2, 9, 1, [20])  # Return Delay Time
    assert writer.addParam(3, 112, 4, list((321).to_bytes(4, "little")))  # Profile Velocity
    assert writer.txPacket() == COMM_SUCCESS
    bus.settle()
    reader = GroupBulkRead(sdk.port, sdk.ph)
    assert reader.addParam(1, 65, 1)
    assert reader.addParam(2, 9, 1)
    assert reader.addParam(3, 112, 4)
    assert reader.txRxPacket() == COMM_SUCCESS
    assert (reader.getData(1, 65, 1), reader.getData(2, 9, 1), reader.getData(3, 112, 4)) == (1, 20, 321)
    assert reader.fastBulkRead() == COMM_SUCCESS
    assert (reader.getData(1, 65, 1), reader.getData(2, 9, 1), reader.getData(3, 112, 4)) == (1, 20, 321)


def test_alert_bit_shutdown_and_reboot(bus: EmulatedBus, sdk: SdkLink) -> None:
    from riderlive.dynamixel.emulator.faults import parse_fault

    assert sdk.ph.write1ByteTxRx(sdk.port, 2, 64, 1) == (COMM_SUCCESS, 0)
    bus.apply(parse_fault("overload:2"))
    assert sdk.ph.read1ByteTxRx(sdk.port, 2, 70) == (0x20, COMM_SUCCESS, ALERT_BIT)
    assert sdk.ph.read1ByteTxRx(sdk.port, 2, 64)[0] == 0  # Shutdown turned torque off
    assert sdk.ph.write1ByteTxRx(sdk.port, 2, 64, 1) == (COMM_SUCCESS, ALERT_BIT | StatusError.RESULT_FAIL)
    assert sdk.ph.reboot(sdk.port, 2) == (COMM_SUCCESS, ALERT_BIT)  # the reply precedes the reboot
    assert sdk.ph.read1ByteTxRx(sdk.port, 2, 70) == (0, COMM_SUCCESS, 0)
    assert sdk.ph.write1ByteTxRx(sdk.port, 2, 64, 1) == (COMM_SUCCESS, 0)


def test_an_error_outside_the_shutdown_mask_keeps_torque(bus: EmulatedBus, sdk: SdkLink) -> None:
    from riderlive.dynamixel.emulator.faults import parse_fault

    assert sdk.ph.write1ByteTxRx(sdk.port, 1, 63, 0x20) == (COMM_SUCCESS, 0)  # only overload shuts down
    assert sdk.ph.write1ByteTxRx(sdk.port, 1, 64, 1) == (COMM_SUCCESS, 0)
    bus.apply(parse_fault("voltage:1"))
    assert sdk.ph.read1ByteTxRx(sdk.port, 1, 64) == (1, COMM_SUCCESS, ALERT_BIT)


def test_duplicate_ids_are_refused() -> None:
    import pytest

    with pytest.raises(ValueError, match="duplicate"):
        EmulatedBus([ServoSetup(1, "XL430-W250"), ServoSetup(1, "XL330-M288")])


def test_reboot_time_keeps_the_servo_deaf(bus_factory: object) -> None:
    make = bus_factory  # type: ignore[assignment]
    bus = make([ServoSetup(5, "XM430-W350")], reboot_time_s=0.2)  # type: ignore[operator]
    link = open_sdk(bus)
    try:
        rebooted = time.perf_counter()
        assert link.ph.reboot(link.port, 5) == (COMM_SUCCESS, 0)
        assert link.ph.ping(link.port, 5)[1] == COMM_RX_TIMEOUT
        wait_until(lambda: link.ph.ping(link.port, 5) == (1020, COMM_SUCCESS, 0), 5.0, "the servo never came back")
        assert time.perf_counter() - rebooted >= 0.2 - 0.01  # deaf for its reboot time
    finally:
        link.close()


def test_a_servo_without_fast_read_breaks_the_chain(bus_factory: object) -> None:
    make = bus_factory  # type: ignore[assignment]
    servos = [ServoSetup(1, "XL430-W250"), ServoSetup(2, "XM430-W350", fast_read=False), ServoSetup(3, "XL330-M288")]
    bus = make(servos)  # type: ignore[operator]
    link = open_sdk(bus)
    try:
        reader = GroupSyncRead(link.port, link.ph, PRESENT, 4)
        for i in (1, 2, 3):
            reader.addParam(i)
        assert reader.fastSyncRead() != COMM_SUCCESS  # servo 1 starts the packet, nobody continues it
        assert reader.txRxPacket() == COMM_SUCCESS  # plain Sync Read works
        assert [reader.getData(i, PRESENT, 4) for i in (1, 2, 3)] == [2048, 2048, 2048]
    finally:
        link.close()


def test_a_broadcast_factory_reset_is_ignored_from_firmware_42(bus: EmulatedBus, sdk: SdkLink) -> None:
    assert sdk.ph.write1ByteTxRx(sdk.port, 1, 9, 0) == (COMM_SUCCESS, 0)
    sdk.ph.factoryReset(sdk.port, 0xFE, 0x02)  # no reply to a broadcast
    bus.settle()
    assert bus.read_item(1, Item.RETURN_DELAY_TIME) == 0  # firmware 52: ignored
    bus.write_item(1, Item.FIRMWARE_VERSION, 41)  # an old firmware obeys it
    sdk.ph.factoryReset(sdk.port, 0xFE, 0x02)
    bus.settle()
    assert bus.read_item(1, Item.RETURN_DELAY_TIME) == 250
    assert bus.read_item(2, Item.RETURN_DELAY_TIME) == 250  # untouched before: still the default


def test_clear_resets_the_multi_turn_count_only_when_stopped(bus: EmulatedBus, sdk: SdkLink) -> None:
    import dataclasses

    from riderlive.dynamixel.tables import OperatingMode

    assert sdk.ph.write1ByteTxRx(sdk.port, 2, 11, int(OperatingMode.EXTENDED_POSITION)) == (COMM_SUCCESS, 0)
    with bus.lock:
        servo = bus.servo(2)
        servo.state = dataclasses.replace(servo.state, position=3 * 4096 + 100.0)  # three turns and 100 pulses
    assert sdk.ph.clearMultiTurn(sdk.port, 2) == (COMM_SUCCESS, 0)
    assert sdk.ph.read4ByteTxRx(sdk.port, 2, 132)[0] == 100
    assert sdk.ph.write1ByteTxRx(sdk.port, 2, 64, 1) == (COMM_SUCCESS, 0)
    assert sdk.ph.write4ByteTxRx(sdk.port, 2, 116, 20_000) == (COMM_SUCCESS, 0)  # off it goes
    # Moving (122) rises at the servo's next 1 ms control cycle: a CLEAR within the same
    # millisecond would still find it stopped, so wait for the flag (as a host would read it)
    deadline = time.perf_counter() + 1.0
    while sdk.ph.read1ByteTxRx(sdk.port, 2, 122)[0] != 1:
        assert time.perf_counter() < deadline, "the servo never reported Moving"
    assert sdk.ph.clearMultiTurn(sdk.port, 2) == (COMM_SUCCESS, StatusError.RESULT_FAIL)  # moving
    bus.write_item(3, Item.FIRMWARE_VERSION, 41)
    assert sdk.ph.clearMultiTurn(sdk.port, 3) == (COMM_SUCCESS, StatusError.INSTRUCTION)


def test_voltage_outside_the_limits_is_an_input_voltage_error(bus: EmulatedBus, sdk: SdkLink) -> None:
    from riderlive.dynamixel.emulator.faults import parse_fault

    bus.apply(parse_fault("voltage:3:6.5"))  # XL330: 3.5 .. 7.0 V by default
    assert sdk.ph.read2ByteTxRx(sdk.port, 3, 144) == (65, COMM_SUCCESS, 0)
    bus.apply(parse_fault("voltage:3:12.0"))  # an XL330 on a 12 V branch
    assert sdk.ph.read1ByteTxRx(sdk.port, 3, 70) == (int(HardwareError.INPUT_VOLTAGE), COMM_SUCCESS, ALERT_BIT)
    bus.apply(parse_fault("voltage:3:5.0"))
    assert sdk.ph.read1ByteTxRx(sdk.port, 3, 70)[2] == ALERT_BIT  # latched until a reboot
    assert sdk.ph.write2ByteTxRx(sdk.port, 1, 34, 115) == (COMM_SUCCESS, 0)  # Min Voltage Limit 11.5 V
    bus.settle()
    assert bus.read_item(1, Item.HARDWARE_ERROR_STATUS) == int(HardwareError.INPUT_VOLTAGE)  # 11.1 V supply
