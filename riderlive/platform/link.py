"""The platform link codec: COBS framing, CRC-16, sequence numbers, a version byte. No I/O.

``docs/platform-link.md`` is the definition; this module and ``firmware_proto/src/link.c``
implement it, and ``tests/platform/vectors/link_v1.json`` (written by this module) is the
contract both pass. A frame before COBS, little-endian::

    version u8 | type u8 | seq u16 | body ... | crc u16   (CRC-16/IBM-3740 of all before it)

On the wire: COBS(frame) followed by one 0x00. Every message type has one exact length,
derivable from its header and body, so a truncated or padded frame is always rejected.
Positions are signed 16-bit *counts* of 0.01 of the actuator's unit (mm for a linear
actuator, degrees for a rotary arm or a hobby servo): ±327.67 units.
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass
from typing import ClassVar

from riderlive.platform.link_framing import (
    CRC_LEN,
    HEADER_LEN,
    LINK_VERSION,
    MAX_ENCODED,
    MAX_FRAME,
    MIN_FRAME,
    CrcError,
    LengthError,
    OversizeFrame,
    ShortFrame,
    UnknownType,
    VersionError,
    cobs_decode,
    cobs_encode,
    crc16,
)

MAX_ACTUATORS = 8
MAX_NAME = 16
COUNTS_PER_UNIT = 100
"""Position counts per mm (linear) or per degree (rotary, servo)."""
POSITION_MIN, POSITION_MAX = -32768, 32767


# --- vocabularies shared with the firmware ---


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


COUNTERS = (
    "rx_ok",
    "rx_cobs",
    "rx_short",
    "rx_oversize",
    "rx_crc",
    "rx_version",
    "rx_type",
    "rx_length",
    "rx_stale",
    "rx_gap",
    "refused",
    "clipped",
    "limited",
    "deadman",
    "tx_dropped",
)
"""The device's counters in TELEMETRY order (u16 each, wrapping)."""


# --- messages ---


@dataclass(frozen=True)
class Hello:
    """Host -> device: open a session (resets the device's seq window; parks a moving device)."""

    TYPE: ClassVar[FrameType] = FrameType.HELLO


@dataclass(frozen=True)
class Target:
    """Host -> device: one position per actuator, counts (see :data:`COUNTS_PER_UNIT`)."""

    TYPE: ClassVar[FrameType] = FrameType.TARGET
    positions: tuple[int, ...]


@dataclass(frozen=True)
class Arm:
    """Host -> device: operator arm; ``device`` must be the device's own name."""

    TYPE: ClassVar[FrameType] = FrameType.ARM
    device: str


@dataclass(frozen=True)
class Home:
    """Host -> device: operator-requested homing (moves, so it names the device too)."""

    TYPE: ClassVar[FrameType] = FrameType.HOME
    device: str


@dataclass(frozen=True)
class Disarm:
    TYPE: ClassVar[FrameType] = FrameType.DISARM


@dataclass(frozen=True)
class Park:
    TYPE: ClassVar[FrameType] = FrameType.PARK


@dataclass(frozen=True)
class EStop:
    TYPE: ClassVar[FrameType] = FrameType.ESTOP


@dataclass(frozen=True)
class Reset:
    TYPE: ClassVar[FrameType] = FrameType.RESET


@dataclass(frozen=True)
class Heartbeat:
    TYPE: ClassVar[FrameType] = FrameType.HEARTBEAT


@dataclass(frozen=True)
class Config:
    """Host -> device: set ``key`` (for actuator ``index``, else 0) to ``value``."""

    TYPE: ClassVar[FrameType] = FrameType.CONFIG
    key: int
    index: int
    value: int


@dataclass(frozen=True)
class HelloReply:
    """Device -> host: who it is. Its version is the frame's version byte."""

    TYPE: ClassVar[FrameType] = FrameType.HELLO_REPLY
    firmware: tuple[int, int]
    profile: int
    actuators: int
    period_us: int
    heartbeat_ms: int
    device: str


@dataclass(frozen=True)
class Status:
    """Device -> host: the answer to one command frame (not to TARGET or HEARTBEAT)."""

    TYPE: ClassVar[FrameType] = FrameType.STATUS
    ack_seq: int
    ack_type: int
    result: int
    state: int
    faults: int


@dataclass(frozen=True)
class Telemetry:
    """Device -> host, every telemetry period while the link is alive, and on a state change."""

    TYPE: ClassVar[FrameType] = FrameType.TELEMETRY
    state: int
    flags: int
    faults: int
    uptime_ms: int
    last_reason: int
    commanded: tuple[int, ...]
    measured: tuple[int, ...]
    counters: tuple[int, ...]

    def counter(self, name: str) -> int:
        return self.counters[COUNTERS.index(name)]


Message = (
    Hello | Target | Arm | Home | Disarm | Park | EStop | Reset | Heartbeat | Config | HelloReply | Status | Telemetry
)
_EMPTY: dict[FrameType, Message] = {m.TYPE: m for m in (Hello(), Disarm(), Park(), EStop(), Reset(), Heartbeat())}


@dataclass(frozen=True)
class Frame:
    seq: int
    message: Message


# --- bodies ---

_CONFIG = struct.Struct("<BBi")
_HELLO_REPLY = struct.Struct("<BBBBHH")
_STATUS = struct.Struct("<HBBBH")
_TELEMETRY = struct.Struct("<BBHIBB")
_COUNTERS = struct.Struct(f"<{len(COUNTERS)}H")


def _printable(raw: bytes) -> bool:
    return all(0x21 <= b <= 0x7E for b in raw)


def _name_body(name: str) -> bytes:
    raw = name.encode("ascii")  # UnicodeEncodeError is a ValueError
    if not 1 <= len(raw) <= MAX_NAME or not _printable(raw):
        raise ValueError(f"device name must be 1..{MAX_NAME} printable ASCII characters, got {name!r}")
    return bytes((len(raw),)) + raw


def _positions_body(values: tuple[int, ...]) -> bytes:
    if not 1 <= len(values) <= MAX_ACTUATORS:
        raise ValueError(f"1..{MAX_ACTUATORS} positions, got {len(values)}")
    return struct.pack(f"<{len(values)}h", *values)


def _body(message: Message) -> bytes:
    match message:
        case Target(positions):
            return bytes((len(positions),)) + _positions_body(positions)
        case Arm(device) | Home(device):
            return _name_body(device)
        case Config(key, index, value):
            return _CONFIG.pack(key, index, value)
        case HelloReply(firmware, profile, actuators, period_us, heartbeat_ms, device):
            return _HELLO_REPLY.pack(*firmware, profile, actuators, period_us, heartbeat_ms) + _name_body(device)
        case Status(ack_seq, ack_type, result, state, faults):
            return _STATUS.pack(ack_seq, ack_type, result, state, faults)
        case Telemetry(state, flags, faults, uptime_ms, last_reason, commanded, measured, counters):
            if len(measured) != len(commanded) or len(counters) != len(COUNTERS):
                raise ValueError("telemetry needs as many measured as commanded positions and every counter")
            head = _TELEMETRY.pack(state, flags, faults, uptime_ms, last_reason, len(commanded))
            return head + _positions_body(commanded) + _positions_body(measured) + _COUNTERS.pack(*counters)
        case _:
            return b""


def frame_bytes(message: Message, seq: int, version: int = LINK_VERSION) -> bytes:
    """The frame before COBS (header, body, CRC). ``struct.error`` / ``ValueError`` on bad fields."""
    head = struct.pack("<BBH", version, message.TYPE, seq) + _body(message)
    return head + struct.pack("<H", crc16(head))


def encode(message: Message, seq: int, version: int = LINK_VERSION) -> bytes:
    """``message`` as it goes on the wire: COBS-framed, with its trailing 0x00."""
    return cobs_encode(frame_bytes(message, seq, version)) + b"\x00"


def _expect(body: bytes, length: int) -> None:
    if len(body) != length:
        raise LengthError(f"body of {len(body)} bytes, expected {length}")


def _name(body: bytes, offset: int) -> str:
    if len(body) <= offset:
        raise LengthError("missing name length")
    size = body[offset]
    if not 1 <= size <= MAX_NAME:
        raise LengthError(f"name of {size} bytes")
    _expect(body, offset + 1 + size)
    if not _printable(body[offset + 1 :]):
        raise LengthError("a name that is not printable ASCII")  # not the shape of the type
    return body[offset + 1 :].decode("ascii")


def _positions(body: bytes, offset: int, count: int) -> tuple[int, ...]:
    return struct.unpack_from(f"<{count}h", body, offset)


def _count(body: bytes, offset: int, per_item: int, tail: int) -> int:
    if len(body) <= offset:
        raise LengthError("missing count")
    count = body[offset]
    if not 1 <= count <= MAX_ACTUATORS:
        raise LengthError(f"count {count}")
    _expect(body, offset + 1 + per_item * count + tail)
    return count


def _message(kind: FrameType, body: bytes) -> Message:
    if kind in _EMPTY:
        _expect(body, 0)
        return _EMPTY[kind]
    match kind:
        case FrameType.TARGET:
            return Target(_positions(body, 1, _count(body, 0, 2, 0)))
        case FrameType.ARM:
            return Arm(_name(body, 0))
        case FrameType.HOME:
            return Home(_name(body, 0))
        case FrameType.CONFIG:
            _expect(body, _CONFIG.size)
            return Config(*_CONFIG.unpack(body))
        case FrameType.HELLO_REPLY:
            device = _name(body, _HELLO_REPLY.size)
            major, minor, profile, actuators, period, heartbeat = _HELLO_REPLY.unpack_from(body)
            return HelloReply((major, minor), profile, actuators, period, heartbeat, device)
        case FrameType.STATUS:
            _expect(body, _STATUS.size)
            return Status(*_STATUS.unpack(body))
        case _:  # TELEMETRY
            n = _count(body, _TELEMETRY.size - 1, 4, _COUNTERS.size)
            state, flags, faults, uptime, reason, _ = _TELEMETRY.unpack_from(body)
            at = _TELEMETRY.size
            commanded, measured = _positions(body, at, n), _positions(body, at + 2 * n, n)
            counters = _COUNTERS.unpack_from(body, at + 4 * n)
            return Telemetry(state, flags, faults, uptime, reason, commanded, measured, counters)


def decode_frame(frame: bytes) -> Frame:
    """A frame before COBS -> :class:`Frame`; raises a :class:`LinkError` (checked in this order:
    short, oversize, crc, version, type, length)."""
    if len(frame) < MIN_FRAME:
        raise ShortFrame(f"{len(frame)} bytes")
    if len(frame) > MAX_FRAME:
        raise OversizeFrame(f"{len(frame)} bytes")
    (crc,) = struct.unpack_from("<H", frame, len(frame) - CRC_LEN)
    if crc16(frame[:-CRC_LEN]) != crc:
        raise CrcError(f"crc {crc:04x} != {crc16(frame[:-CRC_LEN]):04x}")
    version, kind, seq = struct.unpack_from("<BBH", frame)
    if version != LINK_VERSION:
        raise VersionError(version)
    try:
        frame_type = FrameType(kind)
    except ValueError:
        raise UnknownType(f"type 0x{kind:02x}") from None
    return Frame(seq, _message(frame_type, frame[HEADER_LEN:-CRC_LEN]))


def decode(packet: bytes | bytearray) -> Frame:
    """One COBS packet (the bytes between two 0x00) -> :class:`Frame`, or a :class:`LinkError`."""
    if len(packet) > MAX_ENCODED:
        raise OversizeFrame(f"{len(packet)} bytes")
    return decode_frame(cobs_decode(packet))


def to_counts(values: tuple[float, ...] | list[float]) -> tuple[int, ...]:
    """Positions in mm or degrees -> counts, rounded; ``ValueError`` outside ±327.67 or on NaN."""
    counts = []
    for value in values:
        if not POSITION_MIN <= value * COUNTS_PER_UNIT <= POSITION_MAX:  # also false for NaN
            raise ValueError(f"position {value} outside the link's ±{POSITION_MAX / COUNTS_PER_UNIT}")
        counts.append(round(value * COUNTS_PER_UNIT))
    return tuple(counts)
