"""Dynamixel Protocol 2.0 packet codec: pure functions on bytes, no I/O.

Wire format (ROBOTIS e-manual, Protocol 2.0)::

    instruction: FF FF FD 00 | ID | LEN_L LEN_H | INST | params... | CRC_L CRC_H
    status:      FF FF FD 00 | ID | LEN_L LEN_H | 55 | ERR | params... | CRC_L CRC_H

LEN counts the bytes after itself (INST, ERR, stuffed params, CRC). Inside INST..params
every ``FF FF FD`` is followed by an extra ``FD`` (byte stuffing); LEN counts the stuffed
bytes and the CRC covers the stuffed packet. CRC-16 is polynomial 0x8005, initial value
0, unreflected (CRC-16/BUYPASS).

A Fast Sync/Bulk Read reply is one status packet with ID 0xFE whose body is, per servo,
``ERR ID data CRC``; each CRC covers every byte of the packet before it, the last one is
the packet's CRC. It is not byte-stuffed (its layout is positional).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from riderlive.dynamixel.tables import BROADCAST_ID, Instruction

HEADER = b"\xff\xff\xfd\x00"
"""The four bytes that start every packet (the last is reserved, always 0)."""
MIN_LENGTH = 3
"""Smallest LEN: INST + CRC."""
MAX_PACKET = 1024
"""Largest packet (header to CRC) the SDK sends or accepts, bytes."""


def _crc_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return tuple(table)


_CRC_TABLE = _crc_table()


def crc16(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """CRC-16/BUYPASS of ``data``, continuing from ``crc`` (0 to start)."""
    table = _CRC_TABLE
    for byte in bytes(data):
        crc = ((crc << 8) & 0xFFFF) ^ table[((crc >> 8) ^ byte) & 0xFF]
    return crc


def stuff(body: bytes) -> bytes:
    """Insert ``FD`` after every ``FF FF FD`` in ``body`` (INST + params)."""
    out = bytearray()
    for byte in body:
        out.append(byte)
        if byte == 0xFD and len(out) >= 3 and out[-3] == 0xFF and out[-2] == 0xFF:
            out.append(0xFD)
    return bytes(out)


def unstuff(body: bytes) -> bytes:
    """Remove the ``FD`` that follows every ``FF FF FD`` in ``body`` (inverse of stuff)."""
    out = bytearray()
    i = 0
    n = len(body)
    while i < n:
        byte = body[i]
        out.append(byte)
        i += 1
        if byte == 0xFD and len(out) >= 3 and out[-3] == 0xFF and out[-2] == 0xFF and i < n and body[i] == 0xFD:
            i += 1
    return bytes(out)


class ProtocolError(ValueError):
    """A byte sequence that is not a valid Protocol 2.0 packet."""


class CrcError(ProtocolError):
    """The packet's CRC does not match its bytes (carries the packet's ID)."""

    def __init__(self, packet_id: int, expected: int, received: int) -> None:
        self.packet_id = packet_id
        self.expected = expected
        self.received = received
        super().__init__(f"CRC mismatch for id {packet_id}: computed 0x{expected:04x}, received 0x{received:04x}")


class LengthError(ProtocolError):
    """LEN is too small, too large, or disagrees with the bytes present."""


class HeaderError(ProtocolError):
    """The packet does not start with ``FF FF FD 00``."""


@dataclass(frozen=True)
class InstructionPacket:
    """An instruction from the host. ``params`` are unstuffed."""

    id: int
    instruction: int
    params: bytes = b""


@dataclass(frozen=True)
class StatusPacket:
    """A status reply from a servo. ``error`` is the raw ERR byte; ``params`` unstuffed."""

    id: int
    error: int
    params: bytes = b""


def _frame(packet_id: int, body: bytes) -> bytes:
    stuffed = stuff(body)
    length = len(stuffed) + 2
    head = HEADER + bytes((packet_id & 0xFF, length & 0xFF, length >> 8))
    crc = crc16(head + stuffed)
    return head + stuffed + bytes((crc & 0xFF, crc >> 8))


def encode_instruction(packet_id: int, instruction: int, params: bytes = b"") -> bytes:
    """The wire bytes of an instruction packet (stuffed, with CRC)."""
    return _frame(packet_id, bytes((instruction,)) + bytes(params))


def encode_status(packet_id: int, error: int, params: bytes = b"") -> bytes:
    """The wire bytes of a status packet (stuffed, with CRC)."""
    return _frame(packet_id, bytes((Instruction.STATUS, error)) + bytes(params))


def encode_fast_status(entries: Sequence[tuple[int, int, bytes]]) -> bytes:
    """The wire bytes of a Fast Sync/Bulk Read reply for ``(id, error, data)`` entries.

    Not stuffed; each entry's CRC is the running CRC of everything sent before it.
    """
    length = 1 + sum(4 + len(data) for _, _, data in entries)
    out = bytearray(HEADER + bytes((BROADCAST_ID, length & 0xFF, length >> 8, Instruction.STATUS)))
    crc = crc16(out)
    for servo_id, error, data in entries:
        entry = bytes((error, servo_id)) + bytes(data)
        crc = crc16(entry, crc)
        out += entry + bytes((crc & 0xFF, crc >> 8))
        crc = crc16(out[-2:], crc)
    return bytes(out)


def fast_status_chunks(entries: Sequence[tuple[int, int, bytes]]) -> list[bytes]:
    """:func:`encode_fast_status` split into what each servo sends (the first adds the header)."""
    whole = encode_fast_status(entries)
    sizes = [8 + 4 + len(entries[0][2])] + [4 + len(data) for _, _, data in entries[1:]] if entries else []
    chunks, start = [], 0
    for size in sizes:
        chunks.append(whole[start : start + size])
        start += size
    return chunks


def _split(raw: bytes) -> tuple[int, bytes]:
    """Check header, LEN and CRC of one complete packet; return (id, stuffed body)."""
    if len(raw) < 10:
        raise LengthError(f"packet of {len(raw)} bytes is shorter than the 10-byte minimum")
    if raw[:4] != HEADER:
        raise HeaderError(f"packet starts with {raw[:4].hex(' ')}, not ff ff fd 00")
    length = raw[5] | raw[6] << 8
    if length < MIN_LENGTH:
        raise LengthError(f"LEN {length} is below the minimum of {MIN_LENGTH}")
    if len(raw) != length + 7:
        raise LengthError(f"LEN {length} says {length + 7} bytes but the packet has {len(raw)}")
    received = raw[-2] | raw[-1] << 8
    expected = crc16(raw[:-2])
    if received != expected:
        raise CrcError(raw[4], expected, received)
    return raw[4], raw[7:-2]


def decode_instruction(raw: bytes) -> InstructionPacket:
    """Parse one complete instruction packet (checks the CRC before unstuffing)."""
    packet_id, body = _split(raw)
    body = unstuff(body)
    return InstructionPacket(packet_id, body[0], body[1:])


def decode_status(raw: bytes) -> StatusPacket:
    """Parse one complete status packet."""
    packet_id, body = _split(raw)
    body = unstuff(body)
    if body[0] != Instruction.STATUS:
        raise ProtocolError(f"INST 0x{body[0]:02x} is not STATUS (0x55)")
    if len(body) < 2:
        raise LengthError("status packet without an ERR byte")
    return StatusPacket(packet_id, body[1], body[2:])


def decode_fast_status(raw: bytes, lengths: Iterable[int]) -> list[StatusPacket]:
    """Parse a Fast Sync/Bulk Read reply whose entries carry ``lengths`` data bytes each."""
    packet_id, _ = _split(raw)
    if packet_id != BROADCAST_ID or raw[7] != Instruction.STATUS:
        raise ProtocolError("a fast reply has ID 0xFE and INST 0x55")
    out, pos = [], 8
    for size in lengths:
        end = pos + 2 + size + 2
        if end > len(raw):
            raise LengthError("fast reply is shorter than its entries")
        entry_crc = raw[end - 2] | raw[end - 1] << 8
        if entry_crc != crc16(raw[: end - 2]):
            raise CrcError(raw[pos + 1], crc16(raw[: end - 2]), entry_crc)
        out.append(StatusPacket(raw[pos + 1], raw[pos], bytes(raw[pos + 2 : end - 2])))
        pos = end
    if pos != len(raw):
        raise LengthError(f"fast reply has {len(raw) - pos} bytes beyond its entries")
    return out


@dataclass(frozen=True)
class Garbage:
    """Bytes skipped while hunting for a header (line noise, a truncated packet)."""

    data: bytes


class PacketReader:
    """Incremental splitter of a byte stream into complete packets.

    ``feed`` bytes as they arrive; ``packets`` yields each complete packet's raw bytes
    (header to CRC, CRC not yet checked), or :class:`Garbage` for bytes skipped before
    a header. An incomplete packet stays buffered until more bytes come or ``reset``.
    """

    def __init__(self, max_packet: int = MAX_PACKET) -> None:
        self._buf = bytearray()
        self._max = max_packet

    def feed(self, data: bytes) -> None:
        self._buf += data

    def reset(self) -> bytes:
        """Drop buffered bytes (an inter-byte gap aborts a packet) and return them."""
        dropped = bytes(self._buf)
        self._buf.clear()
        return dropped

    @property
    def pending(self) -> int:
        return len(self._buf)

    def packets(self) -> list[bytes | Garbage]:
        out: list[bytes | Garbage] = []
        buf = self._buf
        while buf:
            start = buf.find(HEADER[:3])
            if start < 0:
                keep = 2 if buf.endswith(b"\xff\xff") else 1 if buf.endswith(b"\xff") else 0
                if len(buf) > keep:
                    out.append(Garbage(bytes(buf[: len(buf) - keep])))
                    del buf[: len(buf) - keep]
                break
            if start:
                out.append(Garbage(bytes(buf[:start])))
                del buf[:start]
            if len(buf) < 7:
                break
            length = buf[5] | buf[6] << 8
            if buf[3] != 0 or length < MIN_LENGTH or length + 7 > self._max:
                out.append(Garbage(bytes(buf[:1])))
                del buf[:1]
                continue
            if len(buf) < length + 7:
                break
            out.append(bytes(buf[: length + 7]))
            del buf[: length + 7]
        return out


def u16(value: int) -> bytes:
    """Little-endian 2 bytes."""
    return (value & 0xFFFF).to_bytes(2, "little")


def le_int(data: bytes, signed: bool = False) -> int:
    """Little-endian integer from ``data``."""
    return int.from_bytes(data, "little", signed=signed)
