"""The platform link codec: hand-computed values, round trips and corruption (hypothesis)."""

from __future__ import annotations

import math
import struct

import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from riderlive.platform import link
from riderlive.platform import link_vocab as vocab
from riderlive.platform.link import (
    COUNTERS,
    Arm,
    Config,
    Hello,
    HelloReply,
    Home,
    Status,
    Target,
    Telemetry,
    decode,
    decode_frame,
    encode,
    frame_bytes,
    to_counts,
)
from riderlive.platform.link_framing import (
    MAX_ENCODED,
    SEQ_MOD,
    SEQ_WINDOW,
    CrcError,
    Deframer,
    LengthError,
    LinkError,
    SeqWindow,
    cobs_decode,
    cobs_encode,
    crc16,
)
from riderlive.platform.link_vocab import FrameType, LinkState


def crc16_bitwise(data: bytes) -> int:
    """CRC-16/IBM-3740 straight from its catalogue definition, one bit at a time."""
    crc = 0xFFFF
    for byte in data:
        for bit in range(7, -1, -1):
            top = (crc >> 15) ^ ((byte >> bit) & 1)
            crc = ((crc << 1) & 0xFFFF) ^ (0x1021 if top else 0)
    return crc


def test_crc_check_value() -> None:
    assert crc16(b"123456789") == 0x29B1  # the catalogue's check value
    assert crc16(b"") == 0xFFFF
    assert crc16_bitwise(b"123456789") == 0x29B1


@given(st.binary(max_size=200))
def test_crc_equals_bitwise_definition(data: bytes) -> None:
    assert crc16(data) == crc16_bitwise(data)


@pytest.mark.parametrize(
    ("data", "encoded"),
    [  # the examples of Cheshire & Baker's paper / Wikipedia's COBS article
        ("", "01"),
        ("00", "0101"),
        ("0000", "010101"),
        ("11220033", "03112202 33".replace(" ", "")),
        ("11223344", "0511223344"),
        ("11000000", "0211010101"),
    ],
)
def test_cobs_known_examples(data: str, encoded: str) -> None:
    assert cobs_encode(bytes.fromhex(data)).hex() == encoded
    assert cobs_decode(bytes.fromhex(encoded)).hex() == data


@given(st.binary(max_size=1000))
def test_cobs_round_trip_has_no_zero_and_bounded_overhead(data: bytes) -> None:
    encoded = cobs_encode(data)
    assert 0 not in encoded
    assert len(encoded) <= len(data) + 1 + len(data) // 254
    assert cobs_decode(encoded) == data


positions = st.integers(-32768, 32767)
names = st.text(st.characters(min_codepoint=0x21, max_codepoint=0x7E), min_size=1, max_size=16)
u8, u16 = st.integers(0, 255), st.integers(0, 0xFFFF)


@st.composite
def telemetry(draw: st.DrawFn) -> Telemetry:
    n = draw(st.integers(1, link.MAX_ACTUATORS))
    return Telemetry(
        draw(u8),
        draw(u8),
        draw(u16),
        draw(st.integers(0, 0xFFFFFFFF)),
        draw(u8),
        tuple(draw(st.lists(positions, min_size=n, max_size=n))),
        tuple(draw(st.lists(positions, min_size=n, max_size=n))),
        tuple(draw(st.lists(u16, min_size=len(COUNTERS), max_size=len(COUNTERS)))),
    )


messages = st.one_of(
    st.sampled_from([Hello(), link.Disarm(), link.Park(), link.EStop(), link.Reset(), link.Heartbeat()]),
    st.builds(Target, st.lists(positions, min_size=1, max_size=link.MAX_ACTUATORS).map(tuple)),
    st.builds(Arm, names),
    st.builds(Home, names),
    st.builds(Config, u8, u8, st.integers(-(2**31), 2**31 - 1)),
    st.builds(HelloReply, st.tuples(u8, u8), u8, u8, u16, u16, names),
    st.builds(Status, u16, u8, u8, u8, u16),
    telemetry(),
)


@given(messages, u16)
def test_every_message_round_trips(message: link.Message, seq: int) -> None:
    wire = encode(message, seq)
    assert wire.endswith(b"\x00") and 0 not in wire[:-1]
    assert len(wire) - 1 <= MAX_ENCODED
    frame = decode(wire[:-1])
    assert frame == link.Frame(seq, message)


@given(messages, u16, st.data())
def test_any_burst_up_to_16_bits_is_a_crc_error(message: link.Message, seq: int, data: st.DataObject) -> None:
    """CRC-16 detects every burst of <= 16 bits: 1 or 2 adjacent corrupted bytes of the frame."""
    frame = bytearray(frame_bytes(message, seq))
    at = data.draw(st.integers(0, len(frame) - 2))
    burst = data.draw(st.integers(1, 0xFFFF))
    frame[at] ^= burst >> 8
    frame[at + 1] ^= burst & 0xFF
    with pytest.raises(CrcError):
        decode_frame(bytes(frame))


@given(messages, u16, st.data())
def test_any_truncation_is_rejected(message: link.Message, seq: int, data: st.DataObject) -> None:
    frame = frame_bytes(message, seq)
    cut = data.draw(st.integers(0, len(frame) - 1))
    with pytest.raises(LinkError):
        decode(cobs_encode(frame[:cut]))


@pytest.mark.parametrize(
    "message",
    [Target((1, 2, 3, 4, 5, 6)), Arm("platform"), Hello(), Config(1, 0, 150), Status(1, 3, 0, 4, 0)],
    ids=lambda m: m.TYPE.name,
)
def test_every_single_byte_corruption_on_the_wire_is_rejected(message: link.Message) -> None:
    """Exhaustive: any byte of the packet replaced by any other value (0x00 included, which
    splits it) -> no packet of the result decodes."""
    wire = encode(message, 0x1234)
    for at in range(len(wire) - 1):
        for value in range(256):
            if value == wire[at]:
                continue
            corrupted = wire[:at] + bytes((value,)) + wire[at + 1 :]
            for packet in Deframer().feed(corrupted):
                with pytest.raises(LinkError):
                    decode(packet)


@given(st.binary(max_size=300))
def test_arbitrary_bytes_raise_only_link_errors(packet: bytes) -> None:
    try:
        frame = decode(packet)
    except LinkError:
        return
    assert encode(frame.message, frame.seq)[:-1] == packet  # only a real frame decodes


@given(messages, u16, st.lists(st.tuples(st.integers(0, 200), u8), min_size=1, max_size=8))
def test_arbitrary_corruption_is_rejected_or_a_complete_frame(
    message: link.Message, seq: int, edits: list[tuple[int, int]]
) -> None:
    """Beyond the CRC's guarantees (the tests above), a corrupted packet is rejected, except
    with a probability near 2^-16 (8e-6 measured, docs/platform-link.md "Errors that get
    through"), when it is a complete frame that passes every check: never a partial one."""
    wire = bytearray(encode(message, seq)[:-1])
    for at, value in edits:
        wire[at % len(wire)] = value
    assume(bytes(wire) != encode(message, seq)[:-1])
    for packet in Deframer().feed(bytes(wire) + b"\x00"):
        try:
            frame = decode(packet)
        except LinkError:
            continue
        assert encode(frame.message, frame.seq)[:-1] == packet


def test_a_corruption_the_crc_misses_is_caught_by_the_name_rule() -> None:
    """Three replaced bytes that CRC-16 does not see (found by hypothesis): the CRC holds,
    but the name is no longer printable ASCII, so the frame is rejected as malformed."""
    wire = bytearray(encode(Arm("000000000#00000^"), 18432)[:-1])
    wire[4], wire[21], wire[15] = 252, 155, 173
    frame = cobs_decode(bytes(wire))
    assert crc16(frame[:-2]) == int.from_bytes(frame[-2:], "little")  # the CRC is fooled
    with pytest.raises(LengthError):
        decode(bytes(wire))


@given(st.lists(messages, min_size=1, max_size=10), st.lists(st.integers(1, 40), min_size=1, max_size=50))
def test_deframer_is_chunking_independent(batch: list[link.Message], cuts: list[int]) -> None:
    stream = b"\x00".join(encode(m, i) for i, m in enumerate(batch))
    deframer, packets, at = Deframer(), [], 0
    for cut in cuts * (len(stream) // sum(cuts) + 1):
        packets += deframer.feed(stream[at : at + cut])
        at += cut
    assert [decode(p) for p in packets] == [link.Frame(i, m) for i, m in enumerate(batch)]


def test_deframer_drops_an_overlong_run_and_resyncs() -> None:
    deframer = Deframer()
    good = encode(Hello(), 7)
    assert deframer.feed(b"\x55" * 60) == []
    assert deframer.feed(b"\x55" * 60 + good[:3]) == []  # the run passed MAX_ENCODED: dropped
    assert deframer.oversize == 1
    assert deframer.feed(good[3:]) == []  # the rest of the frame belongs to the dropped run
    assert [decode(p) for p in deframer.feed(good)] == [link.Frame(7, Hello())]
    assert deframer.oversize == 1


@given(u16, st.integers(1, SEQ_WINDOW - 1))
def test_seq_window_accepts_newer_and_drops_repeats_and_older(start: int, ahead: int) -> None:
    window = SeqWindow()
    assert window.check(start) == 0
    assert window.check(start) is None  # a repeat
    assert window.check((start + ahead) % SEQ_MOD) == ahead - 1
    assert window.check(start) is None  # now older
    assert window.check((start + ahead + SEQ_WINDOW) % SEQ_MOD) is None  # too far: stale


def test_to_counts_rounds_and_refuses_what_does_not_fit() -> None:
    assert to_counts([0.0, 150.004, -90.005, 327.67]) == (0, 15000, -9000, 32767)
    for bad in (327.68, -327.69, math.nan, math.inf):
        with pytest.raises(ValueError):
            to_counts([bad])


def test_names_are_printable_ascii() -> None:
    with pytest.raises(ValueError):
        encode(Arm("a b"), 0)
    with pytest.raises(ValueError):
        encode(Arm("é"), 0)
    head = struct.pack("<BBH", 1, FrameType.ARM, 0) + b"\x03a\x7fb"
    with pytest.raises(LengthError):
        decode_frame(head + struct.pack("<H", crc16(head)))


def test_encode_refuses_fields_the_link_cannot_carry() -> None:
    with pytest.raises(ValueError):
        encode(Arm(""), 0)
    with pytest.raises(ValueError):
        encode(Arm("x" * 17), 0)
    with pytest.raises(ValueError):
        encode(Target(()), 0)
    with pytest.raises(ValueError):
        encode(Target((0,) * 9), 0)
    with pytest.raises(struct.error):  # not an int16
        encode(Target((40000,)), 0)


def test_state_labels_are_the_lifecycle_names() -> None:
    assert [s.label for s in LinkState] == [
        "disconnected", "connecting", "disarmed", "homing", "soft_start",
        "running", "parking", "parked", "estop", "fault",
    ]  # fmt: skip
    assert all(t < 0x80 for t in FrameType if t.name in {"HELLO", "TARGET", "ARM", "CONFIG"})


# --- CONFIG ranges (the table the firmware's tests check edge by edge) ---


def test_config_ranges_edges_and_refusals() -> None:
    velocity = vocab.ConfigKey.VELOCITY_LIMIT
    assert vocab.config_refusal(vocab.Profile.PLATFORM6, velocity, 13000) is None
    assert vocab.config_refusal(vocab.Profile.PLATFORM6, velocity, 25000) is None
    assert vocab.config_refusal(vocab.Profile.PLATFORM6, velocity, 12999) == (
        "VELOCITY_LIMIT 12999 is outside 13000..25000 (firmware profile platform6)"
    )
    assert vocab.config_refusal(vocab.Profile.SERVO8, vocab.ConfigKey.ACCELERATION_LIMIT, 300001) is not None
    assert vocab.config_refusal(vocab.Profile.SERVO8, vocab.ConfigKey.SOFT_MIN, 1) is not None  # park (0) outside
    assert vocab.config_refusal(99, velocity, 1) is None  # a profile this host does not know: the device decides
    for ranges in vocab.CONFIG_RANGES.values():
        assert set(ranges) == set(vocab.ConfigKey) and all(lo <= hi for lo, hi in ranges.values())


def test_the_slowest_accepted_limits_park_within_the_bound() -> None:
    """Hand-computed: 14500 counts (out range 0..15000 from park 500) at 25 % of 13000 counts/s
    with 125000 counts/s^2, from full speed: 0.104 + 4.4615 + 0.026 = 4.59 s."""
    assert vocab.firmware_park_s(14500, 13000, 125000) == pytest.approx(0.104 + 14500 / 3250 + 3250 / 125000)
    assert vocab.firmware_park_s(14500, 13000, 125000) == pytest.approx(4.5915, abs=1e-4)
    assert vocab.firmware_park_s(1.0, 100.0, 1.0) == pytest.approx(100.0 + 2.0)  # short: a triangle
    worst = {vocab.Profile.PLATFORM6: 14500, vocab.Profile.PLATFORM3: 14500, vocab.Profile.SERVO8: 9000}
    for profile, distance in worst.items():
        ranges = vocab.CONFIG_RANGES[profile]
        for v in ranges[vocab.ConfigKey.VELOCITY_LIMIT]:
            for a in ranges[vocab.ConfigKey.ACCELERATION_LIMIT]:
                assert vocab.firmware_park_s(distance, v, a) <= vocab.PARK_BOUND_S - 0.2, (profile, v, a)
        slower = ranges[vocab.ConfigKey.VELOCITY_LIMIT][0] * 0.8  # the floor is not far above what the bound needs
        assert (
            vocab.firmware_park_s(distance, slower, ranges[vocab.ConfigKey.ACCELERATION_LIMIT][0]) > vocab.PARK_BOUND_S
        )
