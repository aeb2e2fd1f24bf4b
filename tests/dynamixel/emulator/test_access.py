"""The emulated servo's write checks (riderlive/dynamixel/emulator/access.py), on a register dict."""

from __future__ import annotations

import pytest

from riderlive.dynamixel.emulator.access import write_error
from riderlive.dynamixel.models import model_spec
from riderlive.dynamixel.tables import HardwareError, Item, OperatingMode, StatusError

SPEC = model_spec("XL430-W250")


def registers(**changes: int) -> dict[Item, int]:
    values = {spec.item: spec.default for spec in SPEC}
    values[Item.OPERATING_MODE] = int(OperatingMode.POSITION)
    values.update({Item[k.upper()]: v for k, v in changes.items()})
    return values


def check(address: int, data: bytes, tripped: bool = False, **changes: int) -> StatusError:
    return write_error(SPEC, registers(**changes).__getitem__, tripped, address, data)


def u32(value: int) -> bytes:
    return value.to_bytes(4, "little", signed=True)


def test_bytes_outside_items_and_parts_of_items() -> None:
    goal = SPEC.items[Item.GOAL_POSITION].address
    assert check(goal, u32(2048)) is StatusError.NONE
    assert check(goal, b"") is StatusError.ACCESS
    assert check(goal + 1, b"\x00\x08") is StatusError.DATA_LENGTH  # the middle of an item
    assert check(goal, b"\x00\x08") is StatusError.DATA_LENGTH  # its first half
    assert check(SPEC.table_size - 1, b"\x00\x00") is StatusError.ACCESS  # past the table
    assert check(SPEC.items[Item.PRESENT_POSITION].address, u32(0)) is StatusError.ACCESS  # read-only


def test_eeprom_only_with_torque_off() -> None:
    delay = SPEC.items[Item.RETURN_DELAY_TIME].address
    assert check(delay, b"\x00") is StatusError.NONE
    assert check(delay, b"\x00", torque_enable=1) is StatusError.ACCESS


def test_ranges_and_the_limits_other_registers_set() -> None:
    goal = SPEC.items[Item.GOAL_POSITION].address
    assert check(goal, u32(4096)) is StatusError.DATA_LIMIT  # above Max Position Limit (4095)
    assert check(goal, u32(1000), min_position_limit=1500) is StatusError.DATA_LIMIT
    mode = SPEC.items[Item.OPERATING_MODE].address
    assert check(mode, b"\x02") is StatusError.DATA_RANGE  # no such operating mode
    assert check(mode, bytes((int(OperatingMode.VELOCITY),))) is StatusError.NONE


def test_shutdown_and_a_tripped_watchdog() -> None:
    torque = SPEC.items[Item.TORQUE_ENABLE].address
    overheated = int(HardwareError.OVERHEATING)
    assert check(torque, b"\x01", hardware_error_status=overheated, shutdown=overheated) is StatusError.RESULT_FAIL
    assert check(torque, b"\x01", hardware_error_status=overheated, shutdown=0) is StatusError.NONE
    goal, watchdog = SPEC.items[Item.GOAL_POSITION].address, SPEC.items[Item.BUS_WATCHDOG].address
    assert check(goal, u32(2048), tripped=True) is StatusError.DATA_RANGE
    assert check(watchdog, b"\x05", tripped=True) is StatusError.DATA_RANGE
    assert check(watchdog, b"\x00", tripped=True) is StatusError.NONE  # clearing it is how one recovers


@pytest.mark.parametrize("item", [Item.ID, Item.BAUD_RATE, Item.GOAL_VELOCITY, Item.LED])
def test_each_default_value_may_be_written_back(item: Item) -> None:
    spec = SPEC.items[item]
    assert check(spec.address, spec.default.to_bytes(spec.size, "little", signed=spec.signed)) is StatusError.NONE
