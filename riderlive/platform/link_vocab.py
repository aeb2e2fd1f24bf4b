"""The platform link's vocabularies, shared with the firmware: no I/O, no codec.

Frame types, the device's states (``LinkState``, with the device lifecycle's names),
reasons, faults, flags, CONFIG keys and actuator profiles, as ``firmware_proto/src/``
numbers them (docs/platform-link.md); each profile's CONFIG ranges in counts (0.01 mm or
0.01 deg; counts/s; counts/s^2; ms) and the bound of the firmware's own park (s).
The codec that puts them on the wire is :mod:`riderlive.platform.link`.
"""

from __future__ import annotations

import enum
import math


class FrameType(enum.IntEnum):
    """Byte 1 of a frame. Host -> device below 0x80, device -> host from 0x80."""

    HELLO = 0x01
    TARGET = 0x02
    ARM = 0x03
    DISARM = 0x04
    HOME = 0x05
    PARK = 0x06
    ESTOP = 0x07
    RESET = 0x08
    HEARTBEAT = 0x09
    CONFIG = 0x0A
    HELLO_REPLY = 0x81
    STATUS = 0x82
    TELEMETRY = 0x83


class LinkState(enum.IntEnum):
    """The lifecycle state byte; ``label`` is the published name (coord/LIFECYCLE.md).

    The firmware reports ``DISARMED`` .. ``FAULT``; the first two are the host's own.
    """

    DISCONNECTED = 0
    CONNECTING = 1
    DISARMED = 2
    HOMING = 3
    SOFT_START = 4
    RUNNING = 5
    PARKING = 6
    PARKED = 7
    ESTOP = 8
    FAULT = 9

    @property
    def label(self) -> str:
        return self.name.lower()


class Reason(enum.IntEnum):
    """Result of a command (STATUS) and the last refusal (TELEMETRY)."""

    OK = 0
    NOT_ARMED = 1  # targets outside soft_start / running
    LATCHED = 2  # e-stop or fault latched: reset first
    MOVING = 3  # not while homing, soft_start, running or parking
    WRONG_DEVICE = 4  # arm/home named another device
    ESTOP_INPUT = 5  # the e-stop input is active
    BAD_COUNT = 6  # target count differs from the actuator count
    OUT_OF_RANGE = 7  # config value outside the build's bounds
    UNKNOWN_KEY = 8  # config key or index unknown


class Fault(enum.IntFlag):
    """Latched fault bits (TELEMETRY, STATUS); reset clears them."""

    ESTOP_INPUT = 0x0001
    ESTOP_LINK = 0x0002
    LINK_TIMEOUT = 0x0004
    FOLLOWING_ERROR = 0x0008
    HOMING_TIMEOUT = 0x0010
    LINK_ERRORS = 0x0020  # too many rejected packets while moving: parked
    PARK_TIMEOUT = 0x0040  # a park not over PARK_BOUND_S after it began (a loop starved of steps): outputs off


class Flag(enum.IntFlag):
    """Live condition bits of TELEMETRY."""

    HOMED = 0x01
    ESTOP_INPUT = 0x02
    OUTPUTS_ON = 0x04
    LINK_OK = 0x08
    LIMITED = 0x10  # a soft, velocity or acceleration limit acted this period


class ConfigKey(enum.IntEnum):
    """CONFIG keys; values may only tighten the build's profile (else OUT_OF_RANGE)."""

    HEARTBEAT_TIMEOUT_MS = 1
    TELEMETRY_PERIOD_MS = 2
    SOFT_MIN = 3  # counts, per actuator (index)
    SOFT_MAX = 4
    VELOCITY_LIMIT = 5  # counts/s, per actuator
    ACCELERATION_LIMIT = 6  # counts/s^2, per actuator
    PWM_HZ = 7  # hobby servo pulse rate, 50..330


class Profile(enum.IntEnum):
    """Actuator profiles of the firmware (firmware_proto/src/profile.c)."""

    PLATFORM6 = 1
    PLATFORM3 = 2
    SERVO8 = 3


PARK_BOUND_S = 5.0
"""A device's park ends (outputs off) within this of its first step for any CONFIG it
accepts: the speed and acceleration floors below (firmware ``PARK_BOUND_MS``)."""
PARK_SCALE = 0.25
"""The firmware parks at this fraction of each actuator's speed limit (profile ``park_scale``)."""


def firmware_park_s(distance: float, speed: float, accel: float) -> float:
    """An upper bound of the firmware's park (s) over ``distance`` under the speed and
    acceleration limits (any one unit: counts, m or deg, per s and s^2), starting at full
    speed the wrong way: brake (speed / accel), then a trapezoid at ``PARK_SCALE`` speed.
    The formula of ``firmware_proto/src/profile.h``; test_config_bounds simulates it."""
    cruise = PARK_SCALE * speed
    if distance >= cruise * cruise / accel:
        trapezoid = distance / cruise + cruise / accel
    else:
        trapezoid = 2.0 * math.sqrt(distance / accel)
    return speed / accel + trapezoid


def _ranges(
    soft: tuple[int, int], home_park: tuple[int, int], speed: tuple[int, int], accel: tuple[int, int]
) -> dict[ConfigKey, tuple[int, int]]:
    """A profile's CONFIG ranges (inclusive) from its soft limits, poses and limit ranges (counts)."""
    return {
        ConfigKey.HEARTBEAT_TIMEOUT_MS: (20, 1000),
        ConfigKey.TELEMETRY_PERIOD_MS: (4, 1000),  # the control period .. 1 s
        ConfigKey.SOFT_MIN: (soft[0], min(home_park)),  # the park and home poses stay inside
        ConfigKey.SOFT_MAX: (max(home_park), soft[1]),
        ConfigKey.VELOCITY_LIMIT: speed,  # counts/s: the floor keeps a park within PARK_BOUND_S
        ConfigKey.ACCELERATION_LIMIT: accel,  # counts/s^2
        ConfigKey.PWM_HZ: (50, 330),
    }


_LINEAR_150MM = _ranges((500, 14500), (7500, 500), (13000, 25000), (125000, 500000))
CONFIG_RANGES: dict[Profile, dict[ConfigKey, tuple[int, int]]] = {
    Profile.PLATFORM6: _LINEAR_150MM,
    Profile.PLATFORM3: _LINEAR_150MM,
    Profile.SERVO8: _ranges((-8500, 8500), (0, 0), (8000, 30000), (75000, 300000)),
}
"""The values each profile's CONFIG accepts, inclusive (anything else: OUT_OF_RANGE, counted).
The firmware's ``profile.c`` holds the same facts; ``link_vectors.json`` carries this table
and the C tests send every edge and one beyond it to the device core. SOFT_MIN must also
stay below the current SOFT_MAX and the other way round."""


def config_refusal(profile: int, key: ConfigKey, value: int) -> str | None:
    """Why a device of ``profile`` would refuse CONFIG ``key`` = ``value`` (OUT_OF_RANGE), or None."""
    try:
        lo, hi = CONFIG_RANGES[Profile(profile)][key]
    except ValueError:
        return None  # a profile this host does not know: the device decides
    if lo <= value <= hi:
        return None
    return f"{key.name} {value} is outside {lo}..{hi} (firmware profile {Profile(profile).name.lower()})"
