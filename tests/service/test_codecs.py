"""Wire codecs without a server: decoding rules and the binary layout round trip."""

from __future__ import annotations

import math
import struct

import msgpack
import numpy as np
import orjson
import pytest
from hypothesis import given
from hypothesis import strategies as st

from riderlive.channels import HORSE_INDEX, HORSE_NAMES, RIDER_NAMES
from riderlive.realtime import layout as L
from riderlive.realtime.record import RecordLayout
from riderlive.service.codecs import BadFrame, Subscription, decode_horse_frame, decode_subscription, parse_message
from riderlive.service.rider_frames import BINARY_HEADER, decode_binary_frame, encode_frame

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@given(
    seq=st.integers(0, 2**53),
    times=st.tuples(finite, finite),
    driver=st.integers(0, 2),
    values=st.lists(finite, min_size=L.N_HORSE + L.N_RIDER, max_size=L.N_HORSE + L.N_RIDER),
    rider=st.lists(st.sampled_from(range(L.N_RIDER)), min_size=1, max_size=5, unique=True),
    horse=st.lists(st.sampled_from(range(L.N_HORSE)), max_size=5, unique=True),
)
def test_binary_and_json_carry_the_same_frame(seq, times, driver, values, rider, horse) -> None:
    record = np.zeros(RecordLayout.rider.stop)
    record[RecordLayout.seq.start] = seq
    record[RecordLayout.engine_t.start], record[RecordLayout.source_t.start] = times
    record[RecordLayout.driver.start] = driver
    record[RecordLayout.horse.start :] = values
    for encoding in ("binary", "json"):
        sub = Subscription(tuple(rider), tuple(horse), 1, encoding)
        data = encode_frame(sub, record)
        frame = decode_binary_frame(data) if isinstance(data, bytes) else orjson.loads(data)
        assert frame["seq"] == seq and frame["t"] == times[0] and frame["source_t"] == times[1]
        assert frame["values"] == [record[RecordLayout.rider.start + i] for i in rider]
        assert frame.get("horse", []) == [record[RecordLayout.horse.start + i] for i in horse]


def test_binary_header_layout_is_fixed() -> None:
    assert BINARY_HEADER.size == 40
    record = np.zeros(RecordLayout.rider.stop)
    record[RecordLayout.seq.start] = 7
    record[RecordLayout.rider.start] = 1.5
    data = encode_frame(Subscription(rider=(0,), encoding="binary"), record)
    assert isinstance(data, bytes) and len(data) == 48
    assert data[:4] == b"RLF1" and struct.unpack_from("<H", data, 4) == (40,)
    assert struct.unpack_from("<Q", data, 8) == (7,)
    assert struct.unpack_from("<d", data, 40) == (1.5,)


def test_horse_frame_by_name_by_order_and_errors() -> None:
    f = decode_horse_frame({"t": 1, "values": {"rearPivot.rz": 2}})
    assert f.t == 1.0 and f.values == {HORSE_INDEX["rearPivot.rz"]: 2.0}
    order = (HORSE_INDEX["lfHoof.tx"], HORSE_INDEX["root.ry"])
    assert decode_horse_frame({"t": 0, "v": [1.0, 2.0]}, order).values == dict(zip(order, [1.0, 2.0], strict=True))
    assert len(decode_horse_frame({"t": 0, "v": [0.0] * len(HORSE_NAMES)}).values) == len(HORSE_NAMES)
    for obj, reason in (
        ({"t": 0, "v": [1.0]}, "wrong_type"),
        ({"t": math.nan, "values": {}}, "not_finite"),
        ({"t": 0, "values": {"x.y": 1}}, "unknown_channel"),
        ({"t": 0, "values": []}, "wrong_type"),
        ({"t": None, "values": {}}, "wrong_type"),
    ):
        with pytest.raises(BadFrame) as err:
            decode_horse_frame(obj)
        assert err.value.reason == reason


@given(st.binary(max_size=200))
def test_arbitrary_bytes_never_crash_the_parser(data: bytes) -> None:
    try:
        obj = parse_message(data, 1000)
        decode_horse_frame(obj)
    except BadFrame:
        pass


def test_msgpack_and_size_limit() -> None:
    assert parse_message(msgpack.packb({"t": 1.0}), 100) == {"t": 1.0}
    with pytest.raises(BadFrame, match="exceeds"):
        parse_message("x" * 101, 100)


def test_subscription_rules() -> None:
    sub = decode_subscription({"channels": ["head.rz"], "rate": 30}, Subscription(), 120.0)
    assert sub.rider == (RIDER_NAMES.index("head.rz"),) and sub.decimation == 4
    assert decode_subscription({}, sub, 120.0) == sub
    for bad in ({"encoding": "xml"}, {"decimation": 0}, {"rate": -1}, {"horse_channels": ["nope"]}):
        with pytest.raises(BadFrame):
            decode_subscription(bad, sub, 120.0)


@given(text=st.text(max_size=400), limit=st.integers(1, 1200))
def test_the_size_limit_counts_utf8_bytes(text: str, limit: int) -> None:
    message = orjson.dumps({"pad": text}).decode()
    size = len(message.encode("utf-8", "surrogatepass"))
    if size > limit:
        with pytest.raises(BadFrame, match="exceeds"):
            parse_message(message, limit)
    else:
        assert parse_message(message, limit) == {"pad": text}


@given(
    rate=st.one_of(finite, st.sampled_from([1e-300, 1e-10, 5e-324, 0.0, -1.0, 1e308])),
    decimation=st.integers(-(2**70), 2**70),
)
def test_subscribe_numbers_are_range_checked_naming_the_field(rate: float, decimation: int) -> None:
    for obj, name in (({"rate": rate}, "'rate'"), ({"decimation": decimation}, "'decimation'")):
        try:
            sub = decode_subscription(obj, Subscription(), 120.0)
        except BadFrame as exc:
            assert name in str(exc)
            continue
        assert 1 <= sub.decimation <= 1000
