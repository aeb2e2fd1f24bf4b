"""The platform link codec: COBS framing, CRC-16, sequence numbers, a version byte. No I/O.

``docs/platform-link.md`` is the definition; this module and ``firmware_proto/src/link.c``
implement it, and ``tests/platform/vectors/link_v1.json`` (written by this module) is the
contract both pass. A frame before COBS, little-endian::

    version u8 | type u8 | seq u16 | body ... | crc u16   (CRC-16/IBM-3740 of all before it)

On the wire: COBS(frame) followed by one 0x00. Every message type has one exact length,
derivable from its header and body, so a truncated or padded frame is always rejected.
Positions are signed 16-bit *counts* of 0.01 of the actuator's unit (mm for a linear
actuator, degrees for a rotary arm or a hobby servo): ±327.67 units.

The vocabularies (frame types, states, reasons, faults, flags, CONFIG keys, profiles, CONFIG
ranges) are :mod:`riderlive.platform.link_vocab`; here: the messages, ``encode``, ``decode``.
"""

from __future__ import annotations

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
from riderlive.platform.link_vocab import FrameType

MAX_ACTUATORS = 8
MAX_NAME = 16
COUNTS_PER_UNIT = 100
"""Position counts per mm (linear) or per degree (rotary, servo)."""
POSITION_MIN, POSITION_MAX = -32768, 32767


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
