"""Test vectors of the platform link, written by the Python codec: the contract of the firmware.

    python -m riderlive.platform.link_vectors            # rewrite firmware_proto/test/link_vectors.json
    python -m riderlive.platform.link_vectors --check    # exit 1 if the committed file differs

``firmware_proto/test/test_vectors.c`` and ``tests/platform/test_link_vectors.py`` both pass
these, so the two codecs cannot drift apart silently. Hex strings are the bytes; ``fields``
are the message's fields by the names of ``docs/platform-link.md``.
"""

from __future__ import annotations

import argparse
import json
import struct
import sys
from dataclasses import asdict
from pathlib import Path
from typing import Any

from riderlive.platform import link, link_framing, link_vocab
from riderlive.platform.link import (
    COUNTERS,
    Arm,
    Config,
    Disarm,
    EStop,
    Heartbeat,
    Hello,
    HelloReply,
    Home,
    Message,
    Park,
    Reset,
    Status,
    Target,
    Telemetry,
)
from riderlive.platform.link_framing import SeqWindow
from riderlive.platform.link_vocab import ConfigKey, Fault, Flag, FrameType, LinkState, Profile, Reason

DEFAULT_PATH = Path(__file__).resolve().parents[2] / "firmware_proto" / "test" / "link_vectors.json"

MESSAGES: list[tuple[str, int, Message]] = [
    ("hello", 0, Hello()),
    ("target_6", 1, Target((0, 15000, -15000, 32767, -32768, 255))),
    ("target_3", 2, Target((7500, 7500, 7500))),
    ("target_8_zeros", 3, Target((0,) * 8)),
    ("arm", 4, Arm("platform")),
    ("arm_max_name", 5, Arm("p" * link.MAX_NAME)),
    ("home", 6, Home("puppet")),
    ("disarm", 7, Disarm()),
    ("park", 8, Park()),
    ("estop", 0xFFFF, EStop()),
    ("reset", 0x0100, Reset()),
    ("heartbeat", 0x00FF, Heartbeat()),
    ("config_heartbeat", 9, Config(ConfigKey.HEARTBEAT_TIMEOUT_MS, 0, 150)),
    ("config_soft_min", 10, Config(ConfigKey.SOFT_MIN, 5, -2_000_000_000)),
    ("hello_reply", 0, HelloReply((0, 1), Profile.PLATFORM6, 6, 4000, 200, "platform")),
    ("status_ok", 1, Status(4, FrameType.ARM, Reason.OK, LinkState.SOFT_START, 0)),
    (
        "status_refused",
        2,
        Status(5, FrameType.ARM, Reason.LATCHED, LinkState.ESTOP, Fault.ESTOP_INPUT | Fault.ESTOP_LINK),
    ),
    (
        "telemetry_6",
        3,
        Telemetry(
            LinkState.RUNNING,
            Flag.HOMED | Flag.OUTPUTS_ON | Flag.LINK_OK,
            0,
            123_456_789,
            Reason.NOT_ARMED,
            (7500, 7400, 7300, 7200, 7100, 7000),
            (7499, 7401, 7300, 7200, 7100, 6998),
            tuple(range(1, len(COUNTERS) + 1)),
        ),
    ),
    (
        "telemetry_8",
        0xFFFE,
        Telemetry(
            LinkState.FAULT,
            Flag.ESTOP_INPUT,
            Fault.LINK_TIMEOUT,
            0xFFFFFFFF,
            Reason.OK,
            (-9000, 9000, 0, 0, 1, -1, 4500, -4500),
            (-9000, 9000, 0, 0, 1, -1, 4500, -4500),
            (0xFFFF,) * len(COUNTERS),
        ),
    ),
]


def _raw_frame(version: int, kind: int, seq: int, body: bytes) -> bytes:
    head = struct.pack("<BBH", version, kind, seq) + body
    return head + struct.pack("<H", link_framing.crc16(head))


def _packet(frame: bytes) -> bytes:
    return link_framing.cobs_encode(frame) + b"\x00"


def _bad() -> list[tuple[str, bytes]]:
    """(name, wire bytes ending in 0x00) of packets a receiver must drop."""
    target = link.frame_bytes(Target((100, 200, 300, 400, 500, 600)), 20)
    flipped = bytearray(target)
    flipped[7] ^= 0x10
    return [
        ("crc_bit_flip", _packet(bytes(flipped))),
        ("crc_swapped_bytes", _packet(target[:6] + target[7:8] + target[6:7] + target[8:])),
        ("truncated_target", _packet(target[:-3])),
        ("cobs_code_past_end", bytes.fromhex("0511223300")),
        ("cobs_empty_frame", bytes.fromhex("0100")),
        ("short_5_bytes", _packet(target[:5])),
        ("oversize_packet", bytes(range(1, 100)) + b"\x00"),
        ("version_2", _packet(_raw_frame(2, FrameType.HEARTBEAT, 21, b""))),
        ("version_0", _packet(_raw_frame(0, FrameType.TARGET, 22, target[4:-2]))),
        ("type_unknown", _packet(_raw_frame(1, 0x55, 23, b""))),
        ("type_zero", _packet(_raw_frame(1, 0x00, 24, b""))),
        ("length_heartbeat_extra_byte", _packet(_raw_frame(1, FrameType.HEARTBEAT, 25, b"\x00"))),
        ("length_target_count_mismatch", _packet(_raw_frame(1, FrameType.TARGET, 26, b"\x06" + bytes(10)))),
        ("length_target_count_zero", _packet(_raw_frame(1, FrameType.TARGET, 27, b"\x00"))),
        ("length_target_count_9", _packet(_raw_frame(1, FrameType.TARGET, 28, b"\x09" + bytes(18)))),
        ("length_arm_name_long", _packet(_raw_frame(1, FrameType.ARM, 29, b"\x11" + b"x" * 17))),
        ("length_arm_name_empty", _packet(_raw_frame(1, FrameType.ARM, 30, b"\x00"))),
        ("length_arm_name_mismatch", _packet(_raw_frame(1, FrameType.ARM, 31, b"\x05abc"))),
        ("length_arm_name_not_printable", _packet(_raw_frame(1, FrameType.ARM, 33, b"\x03a b"))),
        ("length_config_short", _packet(_raw_frame(1, FrameType.CONFIG, 32, b"\x01\x00\x96\x00"))),
    ]


def _error_of(packet: bytes) -> str:
    try:
        link.decode(packet[:-1])
    except link_framing.LinkError as exc:
        return exc.kind
    raise AssertionError(f"{packet.hex()} decodes")


SEQ_CASES: list[tuple[str, list[int]]] = [
    ("in_order_and_replay", [10, 11, 11, 9, 13, 12, 14]),
    ("wrap_around", [65534, 65535, 0, 1, 65535]),
    ("half_window", [100, 100 + 32767, 100 + 32767 + 32768]),
    ("far_jump_is_stale", [5, 5 + 32768, 6]),
]


def _seq_case(seqs: list[int]) -> dict[str, Any]:
    window = SeqWindow()
    gaps = [window.check(seq % link_framing.SEQ_MOD) for seq in seqs]
    return {
        "seqs": [seq % link_framing.SEQ_MOD for seq in seqs],
        "accepted": [gap is not None for gap in gaps],
        "gaps": [gap or 0 for gap in gaps],
    }


def _stream(frames: list[tuple[str, bytes]], bad: list[tuple[str, bytes]]) -> dict[str, Any]:
    """A byte stream mixing every frame and bad packet, with resync zeros and a run with no
    delimiter long enough to overflow: what a parser yields and counts."""
    wire = bytearray(b"\x00\x00")
    expected: list[str] = []
    for index, (name, packet) in enumerate(frames):
        wire += packet
        expected.append(name)
        wire += bad[index % len(bad)][1]
        if index % 3 == 0:
            wire += b"\x00"
    wire += b"\x7f" * 300 + b"\x00"  # noise longer than any packet, then a resync
    wire += frames[1][1]
    expected.append(frames[1][0])
    deframer = link_framing.Deframer()
    counts = {kind: 0 for kind in ("cobs", "short", "oversize", "crc", "version", "type", "length")}
    decoded = []
    for packet in deframer.feed(bytes(wire)):
        try:
            decoded.append(link.decode(packet))
        except link_framing.LinkError as exc:
            counts[exc.kind] += 1
    counts["oversize"] += deframer.oversize
    lookup = {bytes(p): n for n, p in frames}
    names = [lookup[link.encode(f.message, f.seq)] for f in decoded]
    assert names == expected, (names, expected)
    return {"wire": wire.hex(), "frames": names, "errors": counts}


def _fields(message: Message) -> dict[str, Any]:
    fields: dict[str, Any] = json.loads(json.dumps(asdict(message)))  # tuples -> lists
    return fields


def vectors() -> dict[str, Any]:
    frames = [(name, link.encode(message, seq)) for name, seq, message in MESSAGES]
    bad = _bad()
    return {
        "about": "riderlive platform link vectors; written by riderlive.platform.link_vectors, do not edit",
        "link_version": link_framing.LINK_VERSION,
        "crc": {"name": "CRC-16/IBM-3740", "input": b"123456789".hex(), "check": link_framing.crc16(b"123456789")},
        "cobs": [
            {"data": data.hex(), "encoded": link_framing.cobs_encode(data).hex()}
            for data in (b"", b"\x00", b"\x00\x00", b"\x11\x22\x00\x33", b"\x11\x00", bytes(range(1, 97)))
        ],
        "enums": {
            "type": {t.name: int(t) for t in FrameType},
            "state": {s.label: int(s) for s in LinkState},
            "reason": {r.name: int(r) for r in Reason},
            "fault": {f.name: int(f) for f in Fault if f.name},
            "flag": {f.name: int(f) for f in Flag if f.name},
            "config_key": {k.name: int(k) for k in ConfigKey},
            "profile": {p.name: int(p) for p in Profile},
            "counters": list(COUNTERS),
        },
        "park_bound_ms": round(link_vocab.PARK_BOUND_S * 1000),
        "config_ranges": {
            p.name: {k.name: list(r) for k, r in ranges.items()} for p, ranges in link_vocab.CONFIG_RANGES.items()
        },
        "frames": [
            {
                "name": name,
                "seq": seq,
                "type": int(message.TYPE),
                "fields": _fields(message),
                "frame": link.frame_bytes(message, seq).hex(),
                "wire": wire.hex(),
            }
            for (name, seq, message), (_, wire) in zip(MESSAGES, frames, strict=True)
        ],
        "bad": [{"name": name, "wire": packet.hex(), "error": _error_of(packet)} for name, packet in bad],
        "seq": [{"name": name, **_seq_case(seqs)} for name, seqs in SEQ_CASES],
        "stream": _stream(frames, bad),
    }


def render() -> str:
    return json.dumps(vectors(), indent=1) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--out", type=Path, default=DEFAULT_PATH)
    parser.add_argument("--check", action="store_true", help="compare with --out instead of writing it")
    args = parser.parse_args(argv)
    text = render()
    if args.check:
        same = args.out.exists() and args.out.read_text() == text
        print(f"{args.out}: {'up to date' if same else 'DIFFERS: regenerate it'}")
        return 0 if same else 1
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
