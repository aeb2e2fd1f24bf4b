"""Skeletons in the live protocol: the hello carries them, ``bones: true`` adds rider bone quaternions."""

from __future__ import annotations

import json

import numpy as np
import pytest
from websockets.sync.client import connect

from riderlive.channels import RIDER_NAMES
from riderlive.realtime.record import RecordLayout
from riderlive.service.codecs import BadFrame, Subscription, decode_subscription
from riderlive.service.rider_frames import BINARY_HEADER, BONES_HEADER, decode_binary_frame, encode_frame
from riderlive.skeleton import bone_quaternions, hello_skeletons, rider_rig
from tests.service.live_server import LiveServer
from tests.service.test_publish import frames

N_BONES = len(rider_rig().bones)


def subscribe(ws, **fields: object) -> dict:
    ws.send(json.dumps({"type": "subscribe", **fields}))
    while True:
        message = ws.recv(timeout=5)
        if isinstance(message, str) and json.loads(message)["type"] == "subscribed":
            return json.loads(message)


def test_hello_carries_the_skeletons(server: LiveServer) -> None:
    with connect(server.ws + "/ws/rider") as ws:
        hello = json.loads(ws.recv(timeout=5))
    assert hello["skeletons"] == json.loads(json.dumps(hello_skeletons()))
    keys = list(hello)
    assert keys.index("skeletons") > keys.index("drivers"), "appended after the version-1 fields"


def test_bones_subscriber_gets_unit_quaternions_of_its_frames_others_unchanged(server: LiveServer) -> None:
    with (
        connect(server.ws + "/ws/rider") as plain,
        connect(server.ws + "/ws/rider") as bones_json,
        connect(server.ws + "/ws/rider") as bones_bin,
    ):
        for ws in (plain, bones_json, bones_bin):
            ws.recv(timeout=5)
        assert subscribe(bones_json, bones=True)["bones"] is True
        assert subscribe(bones_bin, bones=True, encoding="binary")["bones"] is True
        got_plain = frames(plain, 30)[-20:]
        got_json = frames(bones_json, 30)[-20:]
        got_bin = frames(bones_bin, 30)[-20:]
    assert all("bones" not in f and len(f["values"]) == len(RIDER_NAMES) for f in got_plain)
    by_seq = {f["seq"]: f for f in got_plain}
    for got in (got_json, got_bin):
        for f in got:
            q = np.array(f["bones"]).reshape(-1, 4)
            assert q.shape == (N_BONES, 4)
            np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
            np.testing.assert_allclose(q.ravel(), bone_quaternions(f["values"]), rtol=0, atol=1e-12)
            if f["seq"] in by_seq:
                assert by_seq[f["seq"]]["values"] == f["values"], "bones change nothing else"
    assert any(f["seq"] in by_seq for f in got_json), "the clients saw common ticks"


def test_binary_bones_extend_the_header_only_when_asked() -> None:
    record = np.arange(RecordLayout.rider.stop, dtype=np.float64)
    record[RecordLayout.driver.start] = 1.0
    bones = np.linspace(-1.0, 1.0, 4 * N_BONES)
    plain = encode_frame(Subscription(encoding="binary"), record, bones)
    with_bones = encode_frame(Subscription(encoding="binary", bones=True, horse=(0, 2)), record, bones)
    assert isinstance(plain, bytes) and isinstance(with_bones, bytes)
    assert int.from_bytes(plain[4:6], "little") == BINARY_HEADER.size, "unchanged for others"
    assert int.from_bytes(with_bones[4:6], "little") == BINARY_HEADER.size + BONES_HEADER.size
    decoded = decode_binary_frame(with_bones)
    assert decoded["bones"] == bones.tolist()
    assert decoded["horse"] == record[[RecordLayout.horse.start, RecordLayout.horse.start + 2]].tolist()
    assert decoded["values"] == record[RecordLayout.rider.start :].tolist()
    assert "bones" not in decode_binary_frame(plain)
    assert json.loads(encode_frame(Subscription(bones=True), record, bones))["bones"] == bones.tolist()


def test_bones_must_be_a_boolean() -> None:
    with pytest.raises(BadFrame) as info:
        decode_subscription({"bones": 1}, Subscription(), 120.0)
    assert info.value.reason == "wrong_type"
