"""The Protocol 2.0 codec against ROBOTIS e-manual vectors, the SDK's own codec, and properties."""

from __future__ import annotations

import pytest
from dynamixel_sdk.protocol2_packet_handler import Protocol2PacketHandler
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.dynamixel import tables
from riderlive.dynamixel.emulator import protocol
from riderlive.dynamixel.emulator.protocol import (
    CrcError,
    Garbage,
    HeaderError,
    InstructionPacket,
    LengthError,
    PacketReader,
    StatusPacket,
    crc16,
    decode_fast_status,
    decode_instruction,
    decode_status,
    encode_fast_status,
    encode_instruction,
    encode_status,
    fast_status_chunks,
    stuff,
    unstuff,
)

# Examples printed in the ROBOTIS e-manual, Protocol 2.0 page.
EMANUAL_VECTORS = [
    # PING id 1, and the reply of an XM430-W210 (model 1030, firmware 38).
    (encode_instruction(1, tables.Instruction.PING), "ff ff fd 00 01 03 00 01 19 4e"),
    (encode_status(1, 0, bytes.fromhex("060426")), "ff ff fd 00 01 07 00 55 00 06 04 26 65 5d"),
    # READ Present Position (132, 4 bytes) from id 1, and the reply 166.
    (
        encode_instruction(1, tables.Instruction.READ, bytes.fromhex("84000400")),
        "ff ff fd 00 01 07 00 02 84 00 04 00 1d 15",
    ),
    (encode_status(1, 0, bytes.fromhex("a6000000")), "ff ff fd 00 01 08 00 55 00 a6 00 00 00 8c c0"),
    # WRITE Goal Position (116) = 512 to id 1, and the empty reply.
    (
        encode_instruction(1, tables.Instruction.WRITE, bytes.fromhex("740000020000")),
        "ff ff fd 00 01 09 00 03 74 00 00 02 00 00 ca 89",
    ),
    (encode_status(1, 0), "ff ff fd 00 01 04 00 55 00 a1 0c"),
]


@pytest.mark.parametrize(("encoded", "expected"), EMANUAL_VECTORS)
def test_emanual_vectors_are_byte_exact(encoded: bytes, expected: str) -> None:
    assert encoded.hex(" ") == expected


def test_emanual_vectors_decode() -> None:
    assert decode_instruction(bytes.fromhex("ff ff fd 00 01 03 00 01 19 4e")) == InstructionPacket(1, 0x01, b"")
    status = decode_status(bytes.fromhex("ff ff fd 00 01 07 00 55 00 06 04 26 65 5d"))
    assert status == StatusPacket(1, 0, bytes.fromhex("060426"))
    assert protocol.le_int(status.params[:2]) == 1030


def test_crc_check_value() -> None:
    assert crc16(b"123456789") == 0xFEE8
    assert crc16(b"") == 0


@settings(deadline=None)  # the shared machine can stall any example
@given(st.binary(max_size=300))
def test_crc_matches_the_sdk_table(data: bytes) -> None:
    sdk = Protocol2PacketHandler()
    assert crc16(data) == sdk.updateCRC(0, list(data), len(data))


@settings(deadline=None)  # the shared machine can stall any example
@given(st.binary(max_size=100), st.binary(max_size=100))
def test_crc_continues_across_chunks(a: bytes, b: bytes) -> None:
    assert crc16(b, crc16(a)) == crc16(a + b)


# Bytes drawn mostly from the stuffing alphabet so FF FF FD runs are common.
stuffy = st.lists(st.sampled_from([0xFF, 0xFD, 0x00, 0x55]), max_size=80).map(bytes)


@settings(deadline=None)  # the shared machine can stall any example
@given(stuffy)
def test_stuffing_round_trips(body: bytes) -> None:
    stuffed = stuff(body)
    assert unstuff(stuffed) == body
    assert len(stuffed) == len(body) + body.count(b"\xff\xff\xfd")
    # After stuffing, no header pattern FF FF FD is followed by anything but FD.
    for i in range(len(stuffed) - 3):
        if stuffed[i : i + 3] == b"\xff\xff\xfd":
            assert stuffed[i + 3] == 0xFD


@settings(deadline=None)  # the shared machine can stall any example
@given(st.integers(0, 252), st.integers(0, 255), stuffy)
def test_instruction_round_trip_and_sdk_agreement(packet_id: int, inst: int, params: bytes) -> None:
    raw = encode_instruction(packet_id, inst, params)
    assert decode_instruction(raw) == InstructionPacket(packet_id, inst, params)
    # The SDK builds the same bytes from the same packet.
    sdk = Protocol2PacketHandler()
    tx = [0] * 7 + [inst, *params, 0, 0]
    tx[4], tx[5], tx[6] = packet_id, (len(params) + 3) & 0xFF, (len(params) + 3) >> 8
    stuffed = sdk.addStuffing(tx)
    total = (stuffed[5] | stuffed[6] << 8) + 7
    stuffed[:4] = [0xFF, 0xFF, 0xFD, 0x00]
    crc = sdk.updateCRC(0, stuffed, total - 2)
    stuffed[total - 2 : total] = [crc & 0xFF, crc >> 8]
    assert bytes(stuffed[:total]) == raw


@settings(deadline=None)  # the shared machine can stall any example
@given(st.integers(0, 252), st.integers(0, 255), stuffy)
def test_status_round_trip(packet_id: int, error: int, params: bytes) -> None:
    raw = encode_status(packet_id, error, params)
    assert decode_status(raw) == StatusPacket(packet_id, error, params)
    assert (raw[5] | raw[6] << 8) == len(raw) - 7


def test_stuffed_length_counts_inserted_bytes() -> None:
    raw = encode_instruction(1, tables.Instruction.WRITE, b"\xff\xff\xfd\x00")
    assert raw[5] == 3 + 4 + 1  # INST + CRC + 4 params + 1 stuffed byte
    assert b"\xff\xff\xfd\xfd" in raw


def test_typed_parse_errors() -> None:
    good = bytearray(encode_instruction(3, 1))
    bad_crc = bytes(good[:-1]) + bytes([good[-1] ^ 0xFF])
    with pytest.raises(CrcError) as info:
        decode_instruction(bad_crc)
    assert info.value.packet_id == 3
    with pytest.raises(HeaderError):
        decode_instruction(b"\xff\xff\xfe\x00" + bytes(good[4:]))
    with pytest.raises(LengthError):
        decode_instruction(bytes(good[:-1]))
    short = bytearray(good)
    short[5] = 2
    with pytest.raises(LengthError):
        decode_instruction(bytes(short))
    with pytest.raises(protocol.ProtocolError):
        decode_status(bytes(good))  # an instruction is not a status


@settings(deadline=None)  # the shared machine can stall any example
@given(
    st.lists(
        st.tuples(st.integers(0, 252), st.integers(0, 255), st.binary(min_size=4, max_size=4)), min_size=1, max_size=8
    )
)
def test_fast_status_round_trip(entries: list[tuple[int, int, bytes]]) -> None:
    raw = encode_fast_status(entries)
    assert len(raw) == 8 + sum(4 + len(d) for *_, d in entries)
    assert b"".join(fast_status_chunks(entries)) == raw
    parsed = decode_fast_status(raw, [4] * len(entries))
    assert [(p.id, p.error, p.params) for p in parsed] == entries


def test_reader_splits_a_stream_and_reports_garbage() -> None:
    a = encode_instruction(1, 1)
    b = encode_instruction(2, 2, bytes.fromhex("84000400"))
    reader = PacketReader()
    reader.feed(b"\x00\x13" + a + b[:5])
    out = reader.packets()
    assert out == [Garbage(b"\x00\x13"), a]
    assert reader.pending == 5
    reader.feed(b[5:])
    assert reader.packets() == [b]
    assert reader.pending == 0


@settings(deadline=None)  # the shared machine can stall any example
@given(st.lists(st.tuples(st.integers(0, 252), stuffy), max_size=5), st.integers(1, 7))
def test_reader_is_chunking_independent(packets: list[tuple[int, bytes]], step: int) -> None:
    wire = [encode_instruction(pid, 3, params) for pid, params in packets]
    stream = b"".join(wire)
    reader = PacketReader()
    got: list[bytes | Garbage] = []
    for i in range(0, len(stream), step):
        reader.feed(stream[i : i + step])
        got += reader.packets()
    assert got == wire
