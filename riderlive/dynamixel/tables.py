"""Dynamixel X-series protocol facts as data: instructions, error bits, control-table items.

The models and their control tables: :mod:`riderlive.dynamixel.models`.

Sources: the ROBOTIS e-manual (Protocol 2.0 page; XL330-M288, XL430-W250 and XM430-W350
control tables). Addresses are byte offsets into the servo's control table; sizes are in
bytes; values are raw register units (positions in pulses of 1/4096 turn, velocities in
0.229 rev/min, profile acceleration in 214.577 rev/min^2, temperatures in deg C,
voltages in 0.1 V, Bus Watchdog in 20 ms, Return Delay Time in 2 us).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

BROADCAST_ID = 0xFE
"""Instruction ID that addresses every servo on the bus."""
MAX_ID = 252
"""Highest ID a servo can have."""
PULSES_PER_TURN = 4096
"""Encoder resolution of every X-series servo (0.088 deg per pulse)."""
POSITION_RANGE = (0, 4095)
"""Goal/limit range in Position Control Mode, pulses."""
EXTENDED_POSITION_RANGE = (-1_048_575, 1_048_575)
"""Goal range in Extended / Current-based Position Control Mode, pulses."""
VELOCITY_UNIT_RPM = 0.229
"""Unit of velocity registers (Profile Velocity, Present Velocity, limits), rev/min."""
ACCELERATION_UNIT_RPM2 = 214.577
"""Unit of Profile Acceleration (velocity-based profile), rev/min^2."""
RETURN_DELAY_UNIT_S = 2e-6
"""Unit of Return Delay Time (9)."""
BUS_WATCHDOG_UNIT_S = 0.020
"""Unit of Bus Watchdog (98)."""


class Instruction(enum.IntEnum):
    """Protocol 2.0 instruction codes (the INST byte)."""

    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REG_WRITE = 0x04
    ACTION = 0x05
    FACTORY_RESET = 0x06
    REBOOT = 0x08
    CLEAR = 0x10
    CONTROL_TABLE_BACKUP = 0x20
    STATUS = 0x55
    SYNC_READ = 0x82
    SYNC_WRITE = 0x83
    FAST_SYNC_READ = 0x8A
    BULK_READ = 0x92
    BULK_WRITE = 0x93
    FAST_BULK_READ = 0x9A


class StatusError(enum.IntEnum):
    """The low 7 bits of a status packet's ERR byte (a number, not a bit field)."""

    NONE = 0
    RESULT_FAIL = 1
    INSTRUCTION = 2
    CRC = 3
    DATA_RANGE = 4
    DATA_LENGTH = 5
    DATA_LIMIT = 6
    ACCESS = 7


ALERT_BIT = 0x80
"""ERR bit 7: the servo has a hardware error; read Hardware Error Status (70)."""


class HardwareError(enum.IntFlag):
    """Bits of Hardware Error Status (70) and of the Shutdown (63) mask."""

    INPUT_VOLTAGE = 0x01
    OVERHEATING = 0x04
    MOTOR_ENCODER = 0x08
    ELECTRICAL_SHOCK = 0x10
    OVERLOAD = 0x20


class OperatingMode(enum.IntEnum):
    """Values of Operating Mode (11)."""

    CURRENT = 0
    VELOCITY = 1
    POSITION = 3
    EXTENDED_POSITION = 4
    CURRENT_BASED_POSITION = 5
    PWM = 16


POSITION_MODES = frozenset(
    {OperatingMode.POSITION, OperatingMode.EXTENDED_POSITION, OperatingMode.CURRENT_BASED_POSITION}
)


class FactoryResetOption(enum.IntEnum):
    """Parameter of FACTORY_RESET: what survives the reset."""

    ALL = 0xFF
    KEEP_ID = 0x01
    KEEP_ID_AND_BAUD = 0x02


class Access(enum.Enum):
    """Who may write an item: R is read-only, RW read-write."""

    R = "R"
    RW = "RW"


class Area(enum.Enum):
    """EEPROM items keep their value across reboots and are locked while torque is on."""

    EEPROM = "EEPROM"
    RAM = "RAM"


class Item(enum.StrEnum):
    """Control-table item names (the same name on every X-series model)."""

    MODEL_NUMBER = "model_number"
    MODEL_INFORMATION = "model_information"
    FIRMWARE_VERSION = "firmware_version"
    ID = "id"
    BAUD_RATE = "baud_rate"
    RETURN_DELAY_TIME = "return_delay_time"
    DRIVE_MODE = "drive_mode"
    OPERATING_MODE = "operating_mode"
    SECONDARY_ID = "secondary_id"
    PROTOCOL_TYPE = "protocol_type"
    HOMING_OFFSET = "homing_offset"
    MOVING_THRESHOLD = "moving_threshold"
    TEMPERATURE_LIMIT = "temperature_limit"
    MAX_VOLTAGE_LIMIT = "max_voltage_limit"
    MIN_VOLTAGE_LIMIT = "min_voltage_limit"
    PWM_LIMIT = "pwm_limit"
    CURRENT_LIMIT = "current_limit"
    VELOCITY_LIMIT = "velocity_limit"
    MAX_POSITION_LIMIT = "max_position_limit"
    MIN_POSITION_LIMIT = "min_position_limit"
    STARTUP_CONFIGURATION = "startup_configuration"
    SHUTDOWN = "shutdown"
    TORQUE_ENABLE = "torque_enable"
    LED = "led"
    STATUS_RETURN_LEVEL = "status_return_level"
    REGISTERED_INSTRUCTION = "registered_instruction"
    HARDWARE_ERROR_STATUS = "hardware_error_status"
    VELOCITY_I_GAIN = "velocity_i_gain"
    VELOCITY_P_GAIN = "velocity_p_gain"
    POSITION_D_GAIN = "position_d_gain"
    POSITION_I_GAIN = "position_i_gain"
    POSITION_P_GAIN = "position_p_gain"
    FEEDFORWARD_2ND_GAIN = "feedforward_2nd_gain"
    FEEDFORWARD_1ST_GAIN = "feedforward_1st_gain"
    BUS_WATCHDOG = "bus_watchdog"
    GOAL_PWM = "goal_pwm"
    GOAL_CURRENT = "goal_current"
    GOAL_VELOCITY = "goal_velocity"
    PROFILE_ACCELERATION = "profile_acceleration"
    PROFILE_VELOCITY = "profile_velocity"
    GOAL_POSITION = "goal_position"
    REALTIME_TICK = "realtime_tick"
    MOVING = "moving"
    MOVING_STATUS = "moving_status"
    PRESENT_PWM = "present_pwm"
    PRESENT_LOAD = "present_load"
    PRESENT_CURRENT = "present_current"
    PRESENT_VELOCITY = "present_velocity"
    PRESENT_POSITION = "present_position"
    VELOCITY_TRAJECTORY = "velocity_trajectory"
    POSITION_TRAJECTORY = "position_trajectory"
    PRESENT_INPUT_VOLTAGE = "present_input_voltage"
    PRESENT_TEMPERATURE = "present_temperature"


@dataclass(frozen=True)
class ItemSpec:
    """One control-table item.

    ``low``/``high`` is the static write range (None for read-only items). ``limit_low``
    /``limit_high`` name items whose present value bounds the write (Goal Position
    between the position limits); ``symmetric_limit`` bounds to +-that item's value.
    """

    item: Item
    address: int
    size: int
    access: Access
    default: int = 0
    low: int | None = None
    high: int | None = None
    signed: bool = False
    limit_low: Item | None = None
    limit_high: Item | None = None
    symmetric_limit: Item | None = None

    @property
    def area(self) -> Area:
        return Area.EEPROM if self.address < 64 else Area.RAM

    @property
    def end(self) -> int:
        return self.address + self.size


def decode_hardware_error(value: int) -> list[HardwareError]:
    """The individual bits set in a Hardware Error Status (70) value, lowest first."""
    return [bit for bit in HardwareError if value & bit]
