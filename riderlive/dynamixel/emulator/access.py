"""The emulated servo's write checks (pure): which WRITE the ROBOTIS e-manual refuses, and why.

:func:`write_error` answers for :class:`~riderlive.dynamixel.emulator.servo.EmulatedServo`
(WRITE, REG_WRITE) from its control table and its registers' present values (``get``),
before anything changes; the status error is the reply's ERR byte:

- bytes outside any item: Access; part of an item: Data Length;
- read-only items, and EEPROM items (address < 64) while Torque Enable is 1: Access;
- values outside an item's range (or a goal while the Bus Watchdog has tripped, and any
  Bus Watchdog but 0 then): Data Range; outside a range another register sets (Goal
  Position vs the position limits, goals vs the PWM, current and velocity limits): Data Limit;
- Torque Enable 1 while a hardware error in Shutdown stands: Result Fail.

Addresses and sizes in bytes, values in the register's own units.
"""

from __future__ import annotations

from collections.abc import Callable

from riderlive.dynamixel.models import ModelSpec
from riderlive.dynamixel.tables import EXTENDED_POSITION_RANGE, Access, Area, Item, ItemSpec, OperatingMode, StatusError

GOAL_ITEMS = frozenset({Item.GOAL_PWM, Item.GOAL_CURRENT, Item.GOAL_VELOCITY, Item.GOAL_POSITION})
"""Items that become read-only while the Bus Watchdog has tripped."""
_MODES = frozenset(int(m) for m in OperatingMode)


def write_error(
    spec: ModelSpec, get: Callable[[Item], int], watchdog_tripped: bool, address: int, data: bytes
) -> StatusError:
    """Why a WRITE of ``data`` at ``address`` would be refused (NONE if allowed); ``get`` reads
    a register's present value, ``watchdog_tripped`` says the Bus Watchdog stopped the servo."""
    end = address + len(data)
    if not data or end > spec.table_size:
        return StatusError.ACCESS
    owner = spec.byte_owner
    covered: list[ItemSpec] = []
    position = address
    while position < end:
        item = owner[position]
        if item is None:
            return StatusError.ACCESS
        if item.address != position or item.end > end:
            return StatusError.DATA_LENGTH
        covered.append(item)
        position = item.end
    torque_on = get(Item.TORQUE_ENABLE) == 1
    for item in covered:
        if item.access is Access.R or (item.area is Area.EEPROM and torque_on):
            return StatusError.ACCESS
    for item in covered:
        raw = data[item.address - address : item.end - address]
        error = value_error(item, int.from_bytes(raw, "little", signed=item.signed), get, watchdog_tripped)
        if error is not StatusError.NONE:
            return error
    return StatusError.NONE


def value_error(spec: ItemSpec, value: int, get: Callable[[Item], int], watchdog_tripped: bool) -> StatusError:
    """Why ``value`` may not go into the item ``spec`` (NONE if it may); see :func:`write_error`."""
    item = spec.item
    if watchdog_tripped and (item in GOAL_ITEMS or (item is Item.BUS_WATCHDOG and value != 0)):
        return StatusError.DATA_RANGE
    if item is Item.TORQUE_ENABLE and value == 1 and get(Item.HARDWARE_ERROR_STATUS) & get(Item.SHUTDOWN):
        return StatusError.RESULT_FAIL
    if item is Item.OPERATING_MODE and value not in _MODES:
        return StatusError.DATA_RANGE
    if item is Item.GOAL_POSITION and get(Item.OPERATING_MODE) != OperatingMode.POSITION:
        low, high = EXTENDED_POSITION_RANGE
        return StatusError.NONE if low <= value <= high else StatusError.DATA_RANGE
    if spec.low is not None and spec.high is not None and not spec.low <= value <= spec.high:
        return StatusError.DATA_RANGE
    if spec.limit_low is not None and value < get(spec.limit_low):
        return StatusError.DATA_LIMIT
    if spec.limit_high is not None and value > get(spec.limit_high):
        return StatusError.DATA_LIMIT
    if spec.symmetric_limit is not None and abs(value) > get(spec.symmetric_limit):
        return StatusError.DATA_LIMIT
    return StatusError.NONE
