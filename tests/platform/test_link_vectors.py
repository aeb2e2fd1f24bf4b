"""The committed link vectors are what the codec writes today, and the codec passes them."""

from __future__ import annotations

import json

import pytest

from riderlive.platform import link, link_vectors
from riderlive.platform.link_framing import Deframer, LinkError, SeqWindow, cobs_decode, cobs_encode, crc16

VECTORS = json.loads(link_vectors.DEFAULT_PATH.read_text())


def test_committed_vectors_equal_regeneration() -> None:
    assert link_vectors.DEFAULT_PATH.read_text() == link_vectors.render(), (
        "run: python -m riderlive.platform.link_vectors"
    )


def test_crc_and_cobs_vectors() -> None:
    assert crc16(bytes.fromhex(VECTORS["crc"]["input"])) == VECTORS["crc"]["check"] == 0x29B1
    for case in VECTORS["cobs"]:
        assert cobs_encode(bytes.fromhex(case["data"])).hex() == case["encoded"]
        assert cobs_decode(bytes.fromhex(case["encoded"])).hex() == case["data"]


@pytest.mark.parametrize("case", VECTORS["frames"], ids=lambda c: c["name"])
def test_frame_vector_decodes_to_its_fields(case: dict) -> None:
    wire = bytes.fromhex(case["wire"])
    assert wire[-1] == 0 and cobs_decode(wire[:-1]).hex() == case["frame"]
    frame = link.decode(wire[:-1])
    assert frame.seq == case["seq"] and frame.message.TYPE.value == case["type"]
    assert json.loads(json.dumps(link_vectors._fields(frame.message))) == case["fields"]


@pytest.mark.parametrize("case", VECTORS["bad"], ids=lambda c: c["name"])
def test_bad_vector_is_rejected_with_its_kind(case: dict) -> None:
    with pytest.raises(LinkError) as caught:
        link.decode(bytes.fromhex(case["wire"])[:-1])
    assert caught.value.kind == case["error"]


def test_seq_and_stream_vectors() -> None:
    for case in VECTORS["seq"]:
        window = SeqWindow()
        verdicts = [window.check(s) for s in case["seqs"]]
        assert [v is not None for v in verdicts] == case["accepted"]
        assert [v or 0 for v in verdicts] == case["gaps"]
    stream = VECTORS["stream"]
    deframer, errors, names = Deframer(), dict.fromkeys(stream["errors"], 0), []
    by_wire = {c["wire"]: c["name"] for c in VECTORS["frames"]}
    for packet in deframer.feed(bytes.fromhex(stream["wire"])):
        try:
            frame = link.decode(packet)
        except LinkError as exc:
            errors[exc.kind] += 1
            continue
        names.append(by_wire[link.encode(frame.message, frame.seq).hex()])
    errors["oversize"] += deframer.oversize
    assert names == stream["frames"] and errors == stream["errors"]
    assert sum(errors.values()) >= len(VECTORS["bad"])
