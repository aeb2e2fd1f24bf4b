"""The saddle on the wire without a server: saddle frames decoded, the saddle subscription's
JSON and binary frames carry the same pose and estimate (hypothesis), the ingest spec."""

from __future__ import annotations

import math
import struct

import numpy as np
import orjson
import pytest
from hypothesis import given
from hypothesis import strategies as st

from riderlive.channels import SADDLE_NAMES
from riderlive.realtime.record import RecordLayout
from riderlive.realtime.saddle_input import GAITS, LOCKS
from riderlive.service.arbiter import HORSE_INPUT, SADDLE_INPUT, Producer
from riderlive.service.codecs import BadFrame, Subscription, channel_order, decode_frame, decode_subscription
from riderlive.service.rider_frames import BINARY_HEADER, SADDLE_HEADER, decode_binary_frame, encode_frame

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
SPEC = SADDLE_INPUT


@given(
    saddle=st.lists(finite, min_size=6, max_size=6),
    lock=st.one_of(st.none(), st.integers(0, len(LOCKS) - 1)),
    gait=st.one_of(st.none(), st.integers(0, len(GAITS) - 1)),
    numbers=st.tuples(finite, finite, finite),
    bones=st.booleans(),
    pose=st.booleans(),
)
def test_binary_and_json_carry_the_same_saddle_and_estimate(saddle, lock, gait, numbers, bones, pose) -> None:
    record = np.arange(RecordLayout.rider.stop, dtype=np.float64)
    record[RecordLayout.driver.start] = 1
    record[RecordLayout.saddle.slice] = saddle
    estimate = [math.nan] * 5 if lock is None else [lock, math.nan if gait is None else gait, *numbers]
    record[RecordLayout.estimate.slice] = estimate
    extra = {"pose": {"rider": np.arange(14.0)}} if pose else {}
    frames = []
    for encoding in ("json", "binary"):
        sub = Subscription(
            rider=(0, 3), horse=(1,), encoding=encoding, bones=bones, saddle=True, pose=("rider",) if pose else ()
        )
        data = encode_frame(sub, record, np.arange(8.0) if bones else None, extra.get("pose"))
        frames.append(decode_binary_frame(data) if isinstance(data, bytes) else orjson.loads(data))
    for frame in frames:
        assert frame["saddle"] == saddle
        assert frame["values"] == [record[RecordLayout.rider.start], record[RecordLayout.rider.start + 3]], (
            "the blocks before are intact"
        )
        if lock is None:
            assert frame["estimate"] is None
        else:
            e = frame["estimate"]
            assert e["lock"] == LOCKS[lock] and e["gait"] == (None if gait is None else GAITS[gait])
            assert [e["stride_hz"], e["phase"], e["age"]] == list(numbers)
    assert frames[0] == {**frames[1], "type": "frame"}


def test_the_saddle_header_block_follows_the_fixed_header() -> None:
    record = np.zeros(RecordLayout.rider.stop)
    record[RecordLayout.saddle.slice] = np.arange(1.0, 7.0)
    record[RecordLayout.estimate.slice] = [3, 1, 1.4, 0.25, 0.004]
    data = encode_frame(Subscription(rider=(0,), encoding="binary", saddle=True), record)
    assert isinstance(data, bytes)
    size = BINARY_HEADER.size + SADDLE_HEADER.size
    assert struct.unpack_from("<H", data, 4) == (size,) and data[7] == 8, "header size and flag bit 3"
    assert struct.unpack_from("<HHBB", data, BINARY_HEADER.size) == (6, 3, 3, 1)
    body = np.frombuffer(data, dtype="<f8", offset=size)
    np.testing.assert_array_equal(body, [0.0, 1, 2, 3, 4, 5, 6, 1.4, 0.25, 0.004])
    assert len(data) == size + 8 * (1 + 6 + 3)


def test_subscription_field_and_errors() -> None:
    sub = decode_subscription({"saddle": True}, Subscription(), 120.0)
    assert sub.saddle and sub.key != Subscription().key and sub.describe(120.0)["saddle"] is True
    assert decode_subscription({"rate": 60}, sub, 120.0).saddle, "omitted: kept"
    with pytest.raises(BadFrame) as err:
        decode_subscription({"saddle": 1}, sub, 120.0)
    assert err.value.reason == "wrong_type"


def test_saddle_frames_decode_on_the_saddle_channels() -> None:
    index, names = SPEC.index, SPEC.names
    assert names == SADDLE_NAMES and SPEC.translations == frozenset({0, 1, 2})
    frame = decode_frame({"t": 2, "values": {"saddle.rz": 3.0}}, None, index, names, "saddle")
    assert frame.values == {5: 3.0}
    order = channel_order(["saddle.ty", "saddle.rz"], index, "saddle")
    assert decode_frame({"t": 2, "v": [0.1, 2.0]}, order, index, names, "saddle").values == {1: 0.1, 5: 2.0}
    for obj, reason, text in (
        ({"t": 0, "values": {"rearPivot.rz": 1.0}}, "unknown_channel", "unknown saddle channel"),
        ({"t": 0, "v": [0.0] * 5}, "wrong_type", "6 numbers"),
        ({"t": 0, "values": {"saddle.ty": math.inf}}, "not_finite", "saddle.ty"),
    ):
        with pytest.raises(BadFrame, match=text) as err:
            decode_frame(obj, None, index, names, "saddle")
        assert err.value.reason == reason


def test_a_saddle_producer_leaves_omitted_axes_missing_and_converts_lengths() -> None:
    saddle = Producer(id=1, name="s", spec=SADDLE_INPUT, length_gain=0.01)  # centimetres in, metres in the service
    low, high = [-1.5] * 3 + [-90.0] * 3, [1.5] * 3 + [90.0] * 3
    values = saddle.merge(saddle.convert({1: 3.0, 5: 2.0}, low, high))
    assert values[1] == pytest.approx(0.03) and values[5] == 2.0, "lengths scaled, angles not"
    assert all(math.isnan(values[i]) for i in (0, 2, 3, 4)), "left out: missing, not repeated"
    with pytest.raises(BadFrame, match=r"saddle.ty = 200.0 is outside its plausible range \[-150, 150\]"):
        saddle.convert({1: 200.0}, low, high)
    horse = Producer(id=2, name="h", spec=HORSE_INPUT)
    assert horse.merge({0: 1.0})[1] == 0.0 and horse.merge({1: 2.0})[0] == 1.0, "horse: omitted channels keep"
