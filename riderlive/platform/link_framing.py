"""Link framing, no I/O: CRC-16, COBS, splitting a byte stream, the sequence window, errors.

Shared by the codec (:mod:`riderlive.platform.link`) and the serial transport; the C side is
``firmware_proto/src/link.c``. ``docs/platform-link.md`` is the definition.
"""

from __future__ import annotations

import binascii
from typing import ClassVar

LINK_VERSION = 1
"""The version byte this side speaks (byte 0 of every frame)."""
HEADER_LEN = 4
CRC_LEN = 2
MIN_FRAME = HEADER_LEN + CRC_LEN
MAX_FRAME = 96
"""Largest frame before COBS, bytes; COBS adds one byte (frames are < 254 bytes)."""
MAX_ENCODED = MAX_FRAME + 1
"""Largest COBS packet between two 0x00 delimiters."""
SEQ_MOD = 1 << 16
SEQ_WINDOW = SEQ_MOD // 2
"""A frame is new when (seq - last) mod 2^16 is within 1 .. SEQ_WINDOW - 1."""


def crc16(data: bytes | bytearray | memoryview) -> int:
    """CRC-16/IBM-3740 (CCITT-FALSE): poly 0x1021, init 0xFFFF, no reflection, no xorout.

    Check value over ``b"123456789"``: 0x29B1. (The stdlib's ``crc_hqx`` is this CRC.)
    """
    return binascii.crc_hqx(data, 0xFFFF)


def cobs_encode(data: bytes | bytearray) -> bytes:
    """Consistent Overhead Byte Stuffing: ``data`` without any 0x00 byte, +1 byte per 254."""
    out = bytearray()
    for run in bytes(data).split(b"\x00"):
        while len(run) >= 254:  # a full block: code 0xFF, no zero implied after it
            out += b"\xff" + run[:254]
            run = run[254:]  # noqa: PLW2901
        out += bytes((len(run) + 1,)) + run
    return bytes(out)


def cobs_decode(packet: bytes | bytearray) -> bytes:
    """Invert :func:`cobs_encode`; raises :class:`CobsError` on a 0x00 or a code past the end."""
    out = bytearray()
    index = 0
    end = len(packet)
    while index < end:
        code = packet[index]
        if code == 0 or index + code > end:
            raise CobsError(f"COBS code {code} at byte {index} of {end}")
        block = packet[index + 1 : index + code]
        if 0 in block:
            raise CobsError(f"0x00 inside a COBS block at byte {index}")
        out += block
        index += code
        if code != 0xFF and index < end:
            out.append(0)
    return bytes(out)


# --- errors: what a receiver counts (the names are the counters' and the vectors') ---


class LinkError(Exception):
    """A packet that is not a frame; ``kind`` names the counter it goes to."""

    kind: ClassVar[str] = "link"


class CobsError(LinkError):
    kind = "cobs"


class ShortFrame(LinkError):
    kind = "short"


class OversizeFrame(LinkError):
    kind = "oversize"


class CrcError(LinkError):
    kind = "crc"


class VersionError(LinkError):
    """The CRC holds but the version byte is not ours; ``version`` is the sender's."""

    kind = "version"

    def __init__(self, version: int) -> None:
        self.version = version
        super().__init__(f"link version {version}, this side speaks {LINK_VERSION}")


class UnknownType(LinkError):
    kind = "type"


class LengthError(LinkError):
    kind = "length"


# --- receiving a byte stream ---


class Deframer:
    """Splits a byte stream at 0x00 into COBS packets. A run longer than :data:`MAX_ENCODED`
    is dropped up to the next 0x00 and counted in ``oversize``; empty packets (idle or resync
    zeros) are skipped."""

    def __init__(self) -> None:
        self._pending = bytearray()
        self._discarding = False
        self.oversize = 0

    def feed(self, data: bytes | bytearray) -> list[bytes]:
        *complete, rest = bytes(data).split(b"\x00")
        packets = []
        for part in complete:
            if not self._discarding:
                self._pending += part
                if 0 < len(self._pending) <= MAX_ENCODED:
                    packets.append(bytes(self._pending))
                elif self._pending:
                    self.oversize += 1
            self._pending.clear()
            self._discarding = False
        if not self._discarding:
            self._pending += rest
            if len(self._pending) > MAX_ENCODED:
                self.oversize += 1
                self._discarding = True
                self._pending.clear()
        return packets


class SeqWindow:
    """Accepts a frame only if its seq is newer than the last accepted one (mod 2^16).

    The first frame after :meth:`restart` (or construction) is accepted whatever its seq.
    """

    def __init__(self) -> None:
        self.last: int | None = None

    def restart(self, seq: int | None = None) -> None:
        self.last = seq

    def check(self, seq: int) -> int | None:
        """Frames skipped before ``seq`` (0 for the next one) if new, and accept it; ``None``
        if stale (a repeat or older: drop it)."""
        if self.last is None:
            self.last = seq
            return 0
        ahead = (seq - self.last) % SEQ_MOD
        if not 0 < ahead < SEQ_WINDOW:
            return None
        self.last = seq
        return ahead - 1
