"""The service's edge against the real server: ranges, clocks that jump, smoothing never frozen."""

from __future__ import annotations

import json
import math
import time

import numpy as np
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect

from riderlive.channels import HORSE_INDEX, RIDER_INDEX
from tests.service.live_server import LiveServer
from tests.service.producers import Follower
from tests.waiting import Pacer, wait_until

RZ = HORSE_INDEX["rearPivot.rz"]


def next_of(ws: ClientConnection, kind: str, timeout: float = 5.0) -> dict:
    deadline = time.perf_counter() + timeout
    while True:
        message = json.loads(ws.recv(timeout=max(0.01, deadline - time.perf_counter())))
        if message["type"] == kind:
            return message


def test_values_outside_their_range_are_rejected_naming_channel_value_and_range(server: LiveServer) -> None:
    before = server.metric("riderlive_bad_frames_total", 'reason="out_of_range"')
    with connect(server.ws + "/ws/horse") as ws:
        ws.recv(timeout=5)
        ws.send(json.dumps({"t": 1.0, "values": {"rearPivot.rz": 2.0, "lfHoof.tx": 1e308}}))
        error = next_of(ws, "error")
        assert error["reason"] == "out_of_range"
        assert "lfHoof.tx" in error["message"] and "1e+308" in error["message"] and "[-5, 5]" in error["message"]
        ws.send(json.dumps({"t": 1.1, "values": {"rearPivot.rx": -91.0}}))
        assert "[-90, 90]" in next_of(ws, "error")["message"]
        # A length scale that would overflow valid values: refused in the hello.
        ws.send(json.dumps({"type": "hello", "length_scale": 9.9e8}))
        error = next_of(ws, "error")
        assert error["reason"] == "out_of_range" and "length_scale" in error["message"]
        # The largest accepted scale: 1 unit is 40 km, outside every hoof range; named in the producer's unit.
        ws.send(json.dumps({"type": "hello", "length_scale": 1e6}))
        ws.send(json.dumps({"t": 1.2, "values": {"lfHoof.ty": 1.0}}))
        error = next_of(ws, "error")
        assert error["reason"] == "out_of_range" and "[-0.000125, 0.000125]" in error["message"], error
    assert server.metric("riderlive_bad_frames_total", 'reason="out_of_range"') == before + 4


def test_a_huge_frame_with_smoothing_on_leaves_the_rider_moving(server: LiveServer) -> None:
    """The reported freeze: smoothing on, one 1e308 frame between good ones."""
    follower = Follower(server.ws)
    ws = connect(server.ws + "/ws/horse").__enter__()
    try:
        ws.recv(timeout=5)
        assert server.request("PATCH", "/api/params", json={"smoothing.time_constant": 0.05}).status_code == 200
        t0, pacer = time.perf_counter(), Pacer(0.005)
        for i in range(240):
            t = time.perf_counter() - t0
            values = {"rearPivot.rz": 4.0 * math.sin(5.0 * t), "lfHoof.tx": 0.3}
            if i == 60:
                values["lfHoof.tx"] = 1e308
            ws.send(json.dumps({"t": t, "values": values}))
            pacer.wait()
        follower.wait_for(lambda f: f["at"] > time.perf_counter() - 0.01)
        late = [f for f in follower.frames if f["at"] > t0 + 0.6 and f["driver"] == "input"]
        assert len(late) > 50
        rider = np.array([f["values"] for f in late])
        assert np.isfinite(rider).all()
        moving = np.abs(np.diff(rider[:, RIDER_INDEX["lower_back.rz"]])) > 0
        assert moving.mean() > 0.9, "the rider follows the horse after the bad frame"
        state = server.get("/api/state").json()
        assert state["counters"]["state_resets"] == 0, "rejected at the edge: the filter never saw it"
    finally:
        ws.close()
        follower.close()
        server.request("PATCH", "/api/params", json={"smoothing.time_constant": 0.0})


def test_a_clock_that_jumps_starts_a_new_segment_and_says_so(server: LiveServer) -> None:
    follower = Follower(server.ws)
    before = server.metric("riderlive_clock_jumps_total", 'direction="backward"')
    forward_before = server.metric("riderlive_clock_jumps_total", 'direction="forward"')
    try:
        with connect(server.ws + "/ws/horse") as ws:
            ws.recv(timeout=5)
            start = time.perf_counter()

            def stream(origin: float, seconds: float, rz: float) -> None:
                t_begin, pacer = time.perf_counter(), Pacer(0.01)
                while (elapsed := time.perf_counter() - t_begin) < seconds:
                    ws.send(json.dumps({"t": origin + elapsed, "values": {"rearPivot.rz": rz}}))
                    pacer.wait()

            stream(100.0, 0.4, 1.0)
            follower.wait_for(lambda f: f["driver"] == "input" and f["horse"][RZ] == 1.0)
            # Each stream's frames are looked for from before it began: once it ends they are
            # held for `hold` (0.5 s) only, which a late look on a loaded host can miss.
            mark = len(follower.frames)
            stream(0.0, 0.6, 2.0)  # a scene reload: the clock restarts at 0
            segment = next_of(ws, "segment")
            assert segment["reason"] == "clock_backward" and segment["segment"] == 1
            assert segment["previous_t"] > 100.0 and 0.0 <= segment["t"] < 0.02 and segment["jump"] < -100.0
            frame = follower.wait_for(lambda f: f["driver"] == "input" and f["horse"][RZ] == 2.0, 10, mark)
            assert frame["source_t"] < 1.0, "the new clock is shown: re-anchored, not dropped"
            mark = len(follower.frames)
            stream(5000.0, 0.3, 3.0)
            segment = next_of(ws, "segment")
            assert segment["reason"] == "clock_forward" and segment["segment"] == 2 and segment["jump"] > 4000.0
            follower.wait_for(lambda f: f["driver"] == "input" and f["horse"][RZ] == 3.0, 10, mark)
            frames = [f for f in follower.frames if f["at"] > start]
            assert all(f["driver"] == "input" for f in frames[frames.index(frame) :]), "never stale in between"
    finally:
        follower.close()
    assert server.metric("riderlive_clock_jumps_total", 'direction="backward"') == before + 1
    assert server.metric("riderlive_clock_jumps_total", 'direction="forward"') == forward_before + 1


def test_producer_names_give_a_bounded_set_of_metric_labels(server: LiveServer) -> None:
    for i in range(40):
        with connect(server.ws + "/ws/horse") as ws:
            ws.recv(timeout=5)
            ws.send(json.dumps({"type": "hello", "name": f"churn-{i}"}))
            ws.send(json.dumps({"t": float(i), "values": {"rearPivot.rz": 1.0}}))
            ws.send(json.dumps({"type": "ping-me-back"}))  # answered with an error: the frame before was handled
            next_of(ws, "error")
    text = server.get("/metrics").text
    labels = [line for line in text.splitlines() if line.startswith("riderlive_frames_in_total{")]
    assert len(labels) <= 32 + 1
    assert server.metric("riderlive_frames_in_total", 'producer="other"') >= 8


def test_message_limits_count_bytes_and_huge_messages_are_counted_and_closed(server: LiveServer) -> None:
    before = server.metric("riderlive_bad_frames_total", 'reason="oversize"')
    with connect(server.ws + "/ws/horse") as ws:
        ws.recv(timeout=5)
        text = json.dumps({"t": 1.0, "values": {}, "pad": "é" * 40000}, ensure_ascii=False)
        assert len(text) < 65536 < len(text.encode())
        ws.send(text)
        error = next_of(ws, "error")
        assert error["reason"] == "oversize" and "65536 bytes" in error["message"]
    with connect(server.ws + "/ws/horse", max_size=None) as ws:
        ws.recv(timeout=5)
        try:
            ws.send(b"\x00" * (16 << 20))  # the server may close while it is still being sent
            while True:
                ws.recv(timeout=10)
        except ConnectionClosed as closed:
            # The service sends a 1009 close frame; a client still sending when the socket
            # closes may get a TCP reset instead, which discards that frame (rcvd None).
            assert closed.rcvd is None or closed.rcvd.code == 1009
    oversize = lambda: server.metric("riderlive_bad_frames_total", 'reason="oversize"')  # noqa: E731
    wait_until(lambda: oversize() >= before + 2, 5.0, "the 16 MB message is counted")


def test_every_subscribe_field_is_range_checked_and_the_client_keeps_its_frames(server: LiveServer) -> None:
    with connect(server.ws + "/ws/rider") as ws:
        assert json.loads(ws.recv(timeout=5))["type"] == "hello"
        for message, field in (
            ({"rate": 1e-300}, "'rate'"),
            ({"rate": 1e-10}, "'rate'"),
            ({"rate": 1e300}, "'rate'"),
            ({"decimation": 10**6}, "'decimation'"),
            ({"channels": ["head.rz", "head.rz"]}, "'channels'"),
            ({"encoding": ["json"]}, "'encoding'"),
            ({"bones": "yes"}, "'bones'"),
        ):
            ws.send(json.dumps({"type": "subscribe", **message}))
            error = next_of(ws, "error")
            assert field in error["message"], (message, error)
        ws.send(json.dumps({"type": "ping", "id": [1, 2]}))
        assert "'id'" in next_of(ws, "error")["message"]
        ws.send(json.dumps({"type": "subscribe", "rate": 0.2}))
        assert next_of(ws, "subscribed")["decimation"] == 1000
        ws.send(json.dumps({"type": "subscribe", "rate": 100000}))
        assert "'rate'" in next_of(ws, "error")["message"]
        ws.send(json.dumps({"type": "subscribe", "rate": 5000}))
        assert next_of(ws, "subscribed")["decimation"] == 1
        frames = [next_of(ws, "frame") for _ in range(20)]
        assert len({f["seq"] for f in frames}) == 20


def test_engine_time_plus_the_epoch_is_this_hosts_monotonic_clock(server: LiveServer) -> None:
    """``engine_epoch`` (hello and /api/state) maps engine time onto CLOCK_MONOTONIC exactly:
    a pong's engine time, read between the ping's send and the pong's arrival, lands between
    them on this process's perf_counter; a frame is ticked (``t``) before it arrives."""
    with connect(server.ws + "/ws/rider") as ws:
        hello = json.loads(ws.recv(timeout=5))
        assert hello["hello_version"] >= 4
        epoch = hello["engine_epoch"]
        assert epoch == server.get("/api/state").json()["engine_epoch"]
        for i in range(5):
            sent = time.perf_counter()
            ws.send(json.dumps({"type": "ping", "id": i}))
            pong = next_of(ws, "pong")
            arrived = time.perf_counter()
            assert pong["id"] == i
            assert sent <= pong["engine_time"] + epoch <= arrived, (sent, pong["engine_time"] + epoch, arrived)
        ws.send(json.dumps({"type": "subscribe"}))
        frame = next_of(ws, "frame")
        assert frame["t"] + epoch <= time.perf_counter()
