"""Consistency of the control-table data (tables.py) with itself and the e-manual's addresses."""

from __future__ import annotations

import itertools

import pytest

from riderlive.dynamixel.models import MODEL_NUMBERS, MODELS, Model, model_spec
from riderlive.dynamixel.tables import Access, Area, HardwareError, Item, decode_hardware_error

# Addresses the rest of the project relies on (X-series, Protocol 2.0).
ADDRESSES = {
    Item.MODEL_NUMBER: (0, 2),
    Item.RETURN_DELAY_TIME: (9, 1),
    Item.OPERATING_MODE: (11, 1),
    Item.HOMING_OFFSET: (20, 4),
    Item.MAX_POSITION_LIMIT: (48, 4),
    Item.MIN_POSITION_LIMIT: (52, 4),
    Item.SHUTDOWN: (63, 1),
    Item.TORQUE_ENABLE: (64, 1),
    Item.HARDWARE_ERROR_STATUS: (70, 1),
    Item.BUS_WATCHDOG: (98, 1),
    Item.PROFILE_ACCELERATION: (108, 4),
    Item.PROFILE_VELOCITY: (112, 4),
    Item.GOAL_POSITION: (116, 4),
    Item.MOVING: (122, 1),
    Item.PRESENT_VELOCITY: (128, 4),
    Item.PRESENT_POSITION: (132, 4),
    Item.PRESENT_TEMPERATURE: (146, 1),
}


@pytest.mark.parametrize("model", list(Model))
def test_items_are_well_formed(model: Model) -> None:
    spec = MODELS[model]
    ordered = list(spec)
    for a, b in itertools.pairwise(ordered):
        assert a.end <= b.address, f"{a.item} overlaps {b.item}"
    assert ordered[-1].end <= spec.table_size
    for item in ordered:
        assert (item.area is Area.EEPROM) == (item.address < 64)
        if item.access is Access.R:
            assert item.low is None and item.high is None
        if item.low is not None and item.high is not None:
            assert item.low <= item.default <= item.high, item.item
        bits = 8 * item.size
        lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if item.signed else (0, (1 << bits) - 1)
        assert lo <= item.default <= hi
    for item, (address, size) in ADDRESSES.items():
        assert (spec.spec(item).address, spec.spec(item).size) == (address, size)
    owner = spec.byte_owner
    for item in ordered:
        assert all(owner[a] is item for a in range(item.address, item.end))
    assert spec.spec(Item.MODEL_NUMBER).default == spec.model_number


def test_model_numbers_and_lookup() -> None:
    assert MODEL_NUMBERS == {1200: Model.XL330_M288, 1060: Model.XL430_W250, 1020: Model.XM430_W350}
    assert model_spec("XL430-W250").model is Model.XL430_W250
    with pytest.raises(ValueError, match="known"):
        model_spec("XL320")
    assert MODELS[Model.XL330_M288].baud_code(4_000_000) == 6
    with pytest.raises(ValueError, match="4500000"):
        MODELS[Model.XL330_M288].baud_code(4_500_000)


def test_current_or_load_per_model() -> None:
    assert MODELS[Model.XL430_W250].has(Item.PRESENT_LOAD) and not MODELS[Model.XL430_W250].has(Item.CURRENT_LIMIT)
    for model in (Model.XL330_M288, Model.XM430_W350):
        assert MODELS[model].has(Item.PRESENT_CURRENT) and MODELS[model].has(Item.GOAL_CURRENT)


def test_decode_hardware_error() -> None:
    assert decode_hardware_error(0x24) == [HardwareError.OVERHEATING, HardwareError.OVERLOAD]
    assert decode_hardware_error(0) == []
