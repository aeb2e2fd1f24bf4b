"""Dynamixel X-series models as data: each one's control table and physical figures.

Sources: the ROBOTIS e-manual (XL330-M288, XL430-W250 and XM430-W350 control tables).
Items, units and the protocol's facts: :mod:`riderlive.dynamixel.tables`.
"""

from __future__ import annotations

import enum
import functools
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field

from riderlive.dynamixel.tables import Access, Item, ItemSpec


class Model(enum.StrEnum):
    """Supported servo models, by their ROBOTIS name."""

    XL330_M288 = "XL330-M288"
    XL430_W250 = "XL430-W250"
    XM430_W350 = "XM430-W350"


@dataclass(frozen=True)
class ModelSpec:
    """Static facts about one servo model: its control table and physical figures."""

    model: Model
    model_number: int
    items: Mapping[Item, ItemSpec]
    fast_sync_read: bool
    """Whether the firmware answers FAST_SYNC_READ / FAST_BULK_READ (0x8A / 0x9A)."""
    table_size: int
    """Bytes of addressable control table (reads beyond are an Access error)."""
    no_load_speed_rpm: float
    """Output speed at the nominal voltage, rev/min: the cap when Profile Velocity is 0."""
    nominal_voltage: float
    """Supply voltage the emulator reports, V."""
    current_unit_ma: float | None
    """Unit of Goal/Present Current, mA; None when the model reports Present Load."""
    baud_rates: Mapping[int, int] = field(default_factory=dict)
    """Baud Rate (8) register value -> bits per second."""

    def __iter__(self) -> Iterator[ItemSpec]:
        return iter(self.ordered)

    @functools.cached_property
    def ordered(self) -> tuple[ItemSpec, ...]:
        """Items by address."""
        return tuple(sorted(self.items.values(), key=lambda s: s.address))

    @functools.cached_property
    def byte_owner(self) -> tuple[ItemSpec | None, ...]:
        """For each control-table address, the item that byte belongs to (None in gaps)."""
        owner: list[ItemSpec | None] = [None] * self.table_size
        for spec in self.items.values():
            owner[spec.address : spec.end] = [spec] * spec.size
        return tuple(owner)

    def spec(self, item: Item) -> ItemSpec:
        return self.items[item]

    def has(self, item: Item) -> bool:
        return item in self.items

    def baud_code(self, baud: int) -> int:
        """The Baud Rate (8) value for ``baud`` bits per second (ValueError if none)."""
        for code, bps in self.baud_rates.items():
            if bps == baud:
                return code
        raise ValueError(f"{self.model.value} has no baud rate {baud}; allowed: {sorted(self.baud_rates.values())}")


_BAUD_X = {0: 9600, 1: 57600, 2: 115200, 3: 1_000_000, 4: 2_000_000, 5: 3_000_000, 6: 4_000_000, 7: 4_500_000}
_BAUD_XL330 = {code: bps for code, bps in _BAUD_X.items() if code <= 6}

R, RW = Access.R, Access.RW


def _common_items(
    *,
    model_number: int,
    temperature_limit: int,
    voltage_range: tuple[int, int],
    voltage_defaults: tuple[int, int],
    velocity_limit: tuple[int, int],
    shutdown: int,
    gains: tuple[int, int, int, int, int],
    baud_max: int,
    drive_mode_max: int,
) -> list[ItemSpec]:
    """Items every supported X-series model shares (defaults and ranges vary)."""
    v_low, v_high = voltage_range
    vel_default, vel_max = velocity_limit
    vi, vp, pd, pi, pp = gains
    return [
        ItemSpec(Item.MODEL_NUMBER, 0, 2, R, model_number),
        ItemSpec(Item.MODEL_INFORMATION, 2, 4, R),
        ItemSpec(Item.FIRMWARE_VERSION, 6, 1, R, 52),
        ItemSpec(Item.ID, 7, 1, RW, 1, 0, 252),
        ItemSpec(Item.BAUD_RATE, 8, 1, RW, 1, 0, baud_max),
        ItemSpec(Item.RETURN_DELAY_TIME, 9, 1, RW, 250, 0, 254),
        ItemSpec(Item.DRIVE_MODE, 10, 1, RW, 0, 0, drive_mode_max),
        ItemSpec(Item.OPERATING_MODE, 11, 1, RW, 3, 0, 16),
        ItemSpec(Item.SECONDARY_ID, 12, 1, RW, 255, 0, 255),
        ItemSpec(Item.PROTOCOL_TYPE, 13, 1, RW, 2, 1, 2),
        ItemSpec(Item.HOMING_OFFSET, 20, 4, RW, 0, -1_044_479, 1_044_479, signed=True),
        ItemSpec(Item.MOVING_THRESHOLD, 24, 4, RW, 10, 0, 1023),
        ItemSpec(Item.TEMPERATURE_LIMIT, 31, 1, RW, temperature_limit, 0, 100),
        ItemSpec(Item.MAX_VOLTAGE_LIMIT, 32, 2, RW, voltage_defaults[1], v_low, v_high),
        ItemSpec(Item.MIN_VOLTAGE_LIMIT, 34, 2, RW, voltage_defaults[0], v_low, v_high),
        ItemSpec(Item.PWM_LIMIT, 36, 2, RW, 885, 0, 885),
        ItemSpec(Item.VELOCITY_LIMIT, 44, 4, RW, vel_default, 0, vel_max),
        ItemSpec(Item.MAX_POSITION_LIMIT, 48, 4, RW, 4095, 0, 4095),
        ItemSpec(Item.MIN_POSITION_LIMIT, 52, 4, RW, 0, 0, 4095),
        ItemSpec(Item.STARTUP_CONFIGURATION, 60, 1, RW, 0, 0, 3),
        ItemSpec(Item.SHUTDOWN, 63, 1, RW, shutdown, 0, 0x3F),
        ItemSpec(Item.TORQUE_ENABLE, 64, 1, RW, 0, 0, 1),
        ItemSpec(Item.LED, 65, 1, RW, 0, 0, 1),
        ItemSpec(Item.STATUS_RETURN_LEVEL, 68, 1, RW, 2, 0, 2),
        ItemSpec(Item.REGISTERED_INSTRUCTION, 69, 1, R),
        ItemSpec(Item.HARDWARE_ERROR_STATUS, 70, 1, R),
        ItemSpec(Item.VELOCITY_I_GAIN, 76, 2, RW, vi, 0, 16383),
        ItemSpec(Item.VELOCITY_P_GAIN, 78, 2, RW, vp, 0, 16383),
        ItemSpec(Item.POSITION_D_GAIN, 80, 2, RW, pd, 0, 16383),
        ItemSpec(Item.POSITION_I_GAIN, 82, 2, RW, pi, 0, 16383),
        ItemSpec(Item.POSITION_P_GAIN, 84, 2, RW, pp, 0, 16383),
        ItemSpec(Item.FEEDFORWARD_2ND_GAIN, 88, 2, RW, 0, 0, 16383),
        ItemSpec(Item.FEEDFORWARD_1ST_GAIN, 90, 2, RW, 0, 0, 16383),
        ItemSpec(Item.BUS_WATCHDOG, 98, 1, RW, 0, 0, 127, signed=True),
        ItemSpec(Item.GOAL_PWM, 100, 2, RW, 0, signed=True, symmetric_limit=Item.PWM_LIMIT),
        ItemSpec(Item.GOAL_VELOCITY, 104, 4, RW, 0, signed=True, symmetric_limit=Item.VELOCITY_LIMIT),
        ItemSpec(Item.PROFILE_ACCELERATION, 108, 4, RW, 0, 0, 32767),
        ItemSpec(Item.PROFILE_VELOCITY, 112, 4, RW, 0, 0, 32767),
        ItemSpec(
            Item.GOAL_POSITION,
            116,
            4,
            RW,
            0,
            signed=True,
            limit_low=Item.MIN_POSITION_LIMIT,
            limit_high=Item.MAX_POSITION_LIMIT,
        ),
        ItemSpec(Item.REALTIME_TICK, 120, 2, R),
        ItemSpec(Item.MOVING, 122, 1, R),
        ItemSpec(Item.MOVING_STATUS, 123, 1, R),
        ItemSpec(Item.PRESENT_PWM, 124, 2, R, signed=True),
        ItemSpec(Item.PRESENT_VELOCITY, 128, 4, R, signed=True),
        ItemSpec(Item.PRESENT_POSITION, 132, 4, R, signed=True),
        ItemSpec(Item.VELOCITY_TRAJECTORY, 136, 4, R, signed=True),
        ItemSpec(Item.POSITION_TRAJECTORY, 140, 4, R, signed=True),
        ItemSpec(Item.PRESENT_INPUT_VOLTAGE, 144, 2, R),
        ItemSpec(Item.PRESENT_TEMPERATURE, 146, 1, R),
    ]


def _table(items: list[ItemSpec]) -> dict[Item, ItemSpec]:
    return {spec.item: spec for spec in items}


XL330_M288 = ModelSpec(
    model=Model.XL330_M288,
    model_number=1200,
    items=_table(
        [
            *_common_items(
                model_number=1200,
                temperature_limit=70,
                voltage_range=(31, 70),
                voltage_defaults=(35, 70),
                velocity_limit=(445, 2047),
                shutdown=0x35,
                gains=(1600, 180, 0, 0, 400),
                baud_max=6,
                drive_mode_max=5,
            ),
            ItemSpec(Item.CURRENT_LIMIT, 38, 2, RW, 1750, 0, 1750),
            ItemSpec(Item.GOAL_CURRENT, 102, 2, RW, 0, signed=True, symmetric_limit=Item.CURRENT_LIMIT),
            ItemSpec(Item.PRESENT_CURRENT, 126, 2, R, signed=True),
        ]
    ),
    fast_sync_read=True,
    table_size=228,
    no_load_speed_rpm=103.0,
    nominal_voltage=5.0,
    current_unit_ma=1.0,
    baud_rates=_BAUD_XL330,
)

XL430_W250 = ModelSpec(
    model=Model.XL430_W250,
    model_number=1060,
    items=_table(
        [
            *_common_items(
                model_number=1060,
                temperature_limit=72,
                voltage_range=(60, 140),
                voltage_defaults=(60, 140),
                velocity_limit=(265, 1023),
                shutdown=0x34,
                gains=(1000, 100, 4000, 0, 640),
                baud_max=7,
                drive_mode_max=13,
            ),
            ItemSpec(Item.PRESENT_LOAD, 126, 2, R, signed=True),
        ]
    ),
    fast_sync_read=True,
    table_size=662,
    no_load_speed_rpm=57.0,
    nominal_voltage=11.1,
    current_unit_ma=None,
    baud_rates=_BAUD_X,
)

XM430_W350 = ModelSpec(
    model=Model.XM430_W350,
    model_number=1020,
    items=_table(
        [
            *_common_items(
                model_number=1020,
                temperature_limit=80,
                voltage_range=(95, 160),
                voltage_defaults=(95, 160),
                velocity_limit=(350, 1023),
                shutdown=0x34,
                gains=(1920, 100, 0, 0, 800),
                baud_max=7,
                drive_mode_max=5,
            ),
            ItemSpec(Item.CURRENT_LIMIT, 38, 2, RW, 1193, 0, 1193),
            ItemSpec(Item.GOAL_CURRENT, 102, 2, RW, 0, signed=True, symmetric_limit=Item.CURRENT_LIMIT),
            ItemSpec(Item.PRESENT_CURRENT, 126, 2, R, signed=True),
        ]
    ),
    fast_sync_read=True,
    table_size=662,
    no_load_speed_rpm=46.0,
    nominal_voltage=12.0,
    current_unit_ma=2.69,
    baud_rates=_BAUD_X,
)

MODELS: dict[Model, ModelSpec] = {spec.model: spec for spec in (XL330_M288, XL430_W250, XM430_W350)}
"""Every supported model, by name."""
MODEL_NUMBERS: dict[int, Model] = {spec.model_number: spec.model for spec in MODELS.values()}
"""Model Number (0) register value -> model."""


def model_spec(model: Model | str) -> ModelSpec:
    """The spec for a model name such as ``"XL430-W250"`` (ValueError naming the choices)."""
    try:
        return MODELS[Model(model)]
    except ValueError:
        raise ValueError(f"unknown servo model {model!r}; known: {', '.join(m.value for m in Model)}") from None
