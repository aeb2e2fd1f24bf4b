"""Bad horse input: each message rejected with an error, counted; the tick never stops."""

from __future__ import annotations

import json

import msgpack
import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from tests.service.live_server import LiveServer

BAD = [
    ("malformed", "{not json"),
    ("malformed", "[1, 2, 3]"),
    ("missing_t", json.dumps({"values": {"rearPivot.rz": 1.0}})),
    ("wrong_type", json.dumps({"t": "soon", "values": {}})),
    ("wrong_type", json.dumps({"t": 1.0, "values": {"rearPivot.rz": "high"}})),
    ("wrong_type", json.dumps({"t": 1.0, "values": {"rearPivot.rz": True}})),
    ("unknown_channel", json.dumps({"t": 1.0, "values": {"tail.rz": 1.0}})),
    ("missing_values", json.dumps({"t": 1.0})),
    ("not_finite", msgpack.packb({"t": 1.0, "values": {"rearPivot.rz": float("nan")}})),
    ("not_finite", msgpack.packb({"t": float("inf"), "values": {}})),
    ("malformed", b"\xc1\xc1\xc1"),
    ("oversize", json.dumps({"t": 1.0, "values": {}, "pad": "x" * 70000})),
    ("unknown_type", json.dumps({"type": "dance"})),
]


def errors_until(ws, n: int) -> list[dict]:
    out = []
    while len(out) < n:
        message = json.loads(ws.recv(timeout=5))
        if message["type"] == "error":
            out.append(message)
    return out


def test_each_bad_message_is_answered_counted_and_survived(server: LiveServer) -> None:
    ticks = server.metric("riderlive_tick_ticks_total")
    before = {reason: server.metric("riderlive_bad_frames_total", f'reason="{reason}"') for reason, _ in BAD}
    with connect(server.ws + "/ws/horse") as ws:
        assert json.loads(ws.recv(timeout=5))["type"] == "welcome"
        for reason, message in BAD:
            ws.send(message)
            (error,) = errors_until(ws, 1)
            assert error["reason"] == reason, message
            assert error["message"]
        ws.send(json.dumps({"t": 1.0, "values": {"rearPivot.rz": 1.0}, "future_field": [1, 2]}))
        control = json.loads(ws.recv(timeout=5))
        assert control == {"type": "control", "driving": True}, "a good frame after bad ones is taken"
    counts = {reason: 0 for reason, _ in BAD}
    for reason, _ in BAD:
        counts[reason] += 1
    for reason, n in counts.items():
        assert server.metric("riderlive_bad_frames_total", f'reason="{reason}"') == before[reason] + n, reason
    assert server.metric("riderlive_tick_ticks_total") > ticks


def test_abuse_closes_only_that_connection(server: LiveServer) -> None:
    with connect(server.ws + "/ws/horse") as abuser, connect(server.ws + "/ws/rider") as reader:
        abuser.recv(timeout=5)
        reader.recv(timeout=5)
        with pytest.raises(ConnectionClosed) as closed:
            for _ in range(300):
                abuser.send("{")
            while True:
                abuser.recv(timeout=5)
        assert closed.value.rcvd is not None and closed.value.rcvd.code == 1008
        frames = 0
        while frames < 20:
            frames += json.loads(reader.recv(timeout=5))["type"] == "frame"


def test_flood_beyond_the_rate_limit_is_rejected(tmp_path) -> None:
    config = "[tick]\nrealtime_priority = false\nspare = false\n[input]\nmax_rate = 50.0\nmax_errors = 1000\n"
    live = LiveServer(config, tmp_path)
    try:
        with connect(live.ws + "/ws/horse") as ws:
            ws.recv(timeout=5)
            for i in range(200):
                ws.send(json.dumps({"t": i * 0.001, "values": {"rearPivot.rz": 1.0}}))
            reasons = []
            while len(reasons) < 150:
                message = json.loads(ws.recv(timeout=5))
                if message["type"] == "error":
                    reasons.append(message["reason"])
        assert set(reasons) == {"rate"}
        assert live.metric("riderlive_bad_frames_total", 'reason="rate"') >= 150
    finally:
        live.stop()
