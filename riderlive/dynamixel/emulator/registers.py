"""Register layout of the emulated servos: struct formats per item and per block.

Derived from the control tables (tables.py) at import: one ``struct`` format per item,
and contiguous groups of items (goals, limits, present values) read or written with a
single struct call, which is what keeps the emulator cheap per packet. :func:`profile_of`
reads the goal and limit blocks as the motion model's :class:`~riderlive.dynamixel.emulator.motion.Profile`
(pulses, pulses/s, pulses/s^2).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

from riderlive.dynamixel.emulator import motion
from riderlive.dynamixel.models import MODELS, ModelSpec
from riderlive.dynamixel.tables import POSITION_MODES, VELOCITY_UNIT_RPM, Item, ItemSpec, OperatingMode


def item_layout(spec: ItemSpec) -> tuple[int, str, str, int]:
    """(address, struct format to read, format to write, mask) of an item."""
    code = {1: "b", 2: "h", 4: "i"}[spec.size]
    return spec.address, "<" + (code if spec.signed else code.upper()), "<" + code.upper(), (1 << (8 * spec.size)) - 1


LAYOUTS = {model: {item: item_layout(spec) for item, spec in MODELS[model].items.items()} for model in MODELS}


@dataclass(frozen=True)
class Block:
    """Contiguous items read or written with one struct call (gaps padded)."""

    address: int
    layout: struct.Struct
    items: tuple[Item, ...]

    def read(self, memory: bytearray) -> dict[Item, int]:
        return dict(zip(self.items, self.layout.unpack_from(memory, self.address), strict=True))

    def write(self, memory: bytearray, values: dict[Item, int]) -> None:
        self.layout.pack_into(memory, self.address, *(values[item] for item in self.items))


def make_block(spec: ModelSpec, wanted: tuple[Item, ...]) -> Block:
    present = sorted((spec.items[item] for item in wanted if spec.has(item)), key=lambda s: s.address)
    fmt, position = "<", present[0].address
    for item in present:
        if item.address < position:
            raise ValueError(f"{item.item} overlaps the previous item")
        code = {1: "b", 2: "h", 4: "i"}[item.size]
        fmt += "x" * (item.address - position) + (code if item.signed else code.upper())
        position = item.end
    return Block(present[0].address, struct.Struct(fmt), tuple(item.item for item in present))


GOAL_BLOCK = (
    Item.BUS_WATCHDOG,
    Item.GOAL_PWM,
    Item.GOAL_CURRENT,
    Item.GOAL_VELOCITY,
    Item.PROFILE_ACCELERATION,
    Item.PROFILE_VELOCITY,
    Item.GOAL_POSITION,
)
LIMIT_BLOCK = (Item.HOMING_OFFSET, Item.MOVING_THRESHOLD, Item.PWM_LIMIT, Item.CURRENT_LIMIT)
OUTPUT_BLOCK = (
    Item.MOVING,
    Item.MOVING_STATUS,
    Item.PRESENT_PWM,
    Item.PRESENT_CURRENT,
    Item.PRESENT_LOAD,
    Item.PRESENT_VELOCITY,
    Item.PRESENT_POSITION,
    Item.VELOCITY_TRAJECTORY,
    Item.POSITION_TRAJECTORY,
    Item.PRESENT_INPUT_VOLTAGE,
    Item.PRESENT_TEMPERATURE,
)
BLOCKS = {
    model: (make_block(spec, GOAL_BLOCK), make_block(spec, LIMIT_BLOCK), make_block(spec, OUTPUT_BLOCK))
    for model, spec in MODELS.items()
}
"""Per model: the (goals, limits, present values) blocks."""


def profile_of(
    spec: ModelSpec, memory: bytearray, *, torque_on: bool, mode: int, external_load: float
) -> tuple[motion.Profile, tuple[int, int, int, int]]:
    """What the registers ask of the motion model (``torque_on``: Torque Enable and no tripped
    watchdog; ``mode``: Operating Mode), and the limits the present values are made with:
    (Homing Offset, Moving Threshold, Current Limit (0 if none), PWM Limit), register units."""
    goals_block, limits_block, _ = BLOCKS[spec.model]
    goals = goals_block.read(memory)
    limits = limits_block.read(memory)
    cap = spec.no_load_speed_rpm / VELOCITY_UNIT_RPM  # Profile Velocity 0 = as fast as the motor goes
    velocity_cap = motion.velocity_from_register(round(min(goals[Item.PROFILE_VELOCITY] or cap, cap)))
    accel = goals[Item.PROFILE_ACCELERATION]
    goal_velocity = None
    if mode == OperatingMode.VELOCITY:
        goal_velocity = motion.velocity_from_register(goals[Item.GOAL_VELOCITY])
    elif mode not in POSITION_MODES:
        goal_velocity = 0.0
    output_limits = (
        limits[Item.HOMING_OFFSET],
        limits[Item.MOVING_THRESHOLD],
        limits.get(Item.CURRENT_LIMIT, 0),
        limits[Item.PWM_LIMIT],
    )
    profile = motion.Profile(
        torque_on=torque_on,
        goal_position=float(goals[Item.GOAL_POSITION] - limits[Item.HOMING_OFFSET]),
        max_velocity=velocity_cap,
        max_acceleration=motion.acceleration_from_register(accel) if accel else math.inf,
        goal_velocity=goal_velocity,
        external_load=external_load,
    )
    return profile, output_limits
