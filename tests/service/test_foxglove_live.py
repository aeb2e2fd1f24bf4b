"""``riderlive serve --foxglove``: the real service and the SDK's server, read by a client of the
Foxglove WebSocket protocol written from its spec (tests/service/foxglove_client.py)."""

from __future__ import annotations

import base64
import os
import re
import socket
import time
from collections.abc import Callable, Iterator

import pytest

from riderlive import timecode as tc
from riderlive.channels import RIDER_NAMES
from riderlive.skeleton import HORSE_RIG, rider_rig
from riderlive.timecode import Rate
from tests.service.conftest import BASE_CONFIG
from tests.service.foxglove_client import FoxgloveClient
from tests.service.live_server import LiveServer
from tests.service.producers import Follower
from tests.waiting import wait_until


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    live = LiveServer(BASE_CONFIG + "\n[foxglove]\nport = 0\nbacklog = 64\n", tmp_path_factory.mktemp("fox"))
    yield live
    live.stop()


def foxglove_port(live: LiveServer) -> int:
    found = (re.search(r"Foxglove WebSocket on port (\d+)", line) for line in live.log)
    return int(next(m.group(1) for m in found if m))


def _wait(predicate: Callable[[], object], timeout: float = 5.0) -> None:
    wait_until(predicate, timeout, poll=0.02)


def test_channels_are_advertised_with_their_schemas(server: LiveServer) -> None:
    client = FoxgloveClient(foxglove_port(server))
    try:
        kinds = {t: (c["schemaName"], c["encoding"]) for t, c in client.channels.items()}
        assert kinds == {
            "/rider/joints": ("riderlive.RiderJoints", "json"),
            "/horse/joints": ("riderlive.HorseJoints", "json"),
            "/tf": ("foxglove.FrameTransforms", "protobuf"),
            "/status": ("riderlive.Status", "json"),
        }
    finally:
        client.close()


def test_joints_and_skeletons_stream(server: LiveServer) -> None:
    client = FoxgloveClient(foxglove_port(server))
    try:
        client.subscribe("/rider/joints", "/horse/joints", "/tf")
        _wait(lambda: len(client.received["/rider/joints"]) >= 100 and len(client.received["/tf"]) >= 3)
        rider = client.json_messages("/rider/joints")
        assert set(rider[-1]) == {"seq", "t", "timecode", *(n.replace(".", "_") for n in RIDER_NAMES)}
        ts = [m["t"] for m in rider]
        assert all(b > a for a, b in zip(ts, ts[1:])), "in order, none twice"
        tc.parse(rider[-1]["timecode"], Rate.FPS_25)  # the service's default rate
        log_times = [t for t, _, _ in client.received["/rider/joints"]]
        assert abs(log_times[-1] / 1e9 - time.time()) < 5.0, "log times are Unix time"
        assert client.json_messages("/horse/joints")
        transforms = client.decoded("/tf")[-1].transforms
        parents = {t.child_frame_id: t.parent_frame_id for t in transforms}
        assert parents["horse"] == "world" and parents["rider"] == "horse/saddle"
        assert len(parents) == 2 + len(HORSE_RIG.bones) + len(rider_rig().bones)
    finally:
        client.close()


def test_an_unknown_channel_gets_an_error(server: LiveServer) -> None:
    client = FoxgloveClient(foxglove_port(server))
    try:
        client.subscribe("/rider/joints", channel_ids=(9999,))
        _wait(lambda: client.status)
        assert client.status[0]["level"] == 2 and "9999" in client.status[0]["message"]
        _wait(lambda: len(client.received["/rider/joints"]) >= 10)  # the good subscription still works
    finally:
        client.close()


def _silent_client(port: int, channel_ids: list[int]) -> socket.socket:
    """A client that subscribes, then never reads (a 4 KiB receive buffer)."""
    raw = socket.create_connection(("127.0.0.1", port))
    raw.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    key = base64.b64encode(os.urandom(16)).decode()
    raw.sendall(
        f"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
        "Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n".encode()
    )
    assert raw.recv(12) == b"HTTP/1.1 101"
    subs = ",".join(f'{{"id":{i + 1},"channelId":{c}}}' for i, c in enumerate(channel_ids))
    payload = f'{{"op":"subscribe","subscriptions":[{subs}]}}'.encode()
    mask = os.urandom(4)
    header = bytes([0x81, 0x80 | 126]) + len(payload).to_bytes(2, "big") + mask
    raw.sendall(header + bytes(b ^ mask[i % 4] for i, b in enumerate(payload)))
    return raw


def test_a_client_that_stops_reading_stalls_nobody(server: LiveServer) -> None:
    port = foxglove_port(server)
    good = FoxgloveClient(port)
    follower = Follower(server.ws)
    ids = [good.channels[t]["id"] for t in ("/rider/joints", "/horse/joints", "/tf")]
    silent = _silent_client(port, ids)
    try:
        good.subscribe("/rider/joints")
        time.sleep(2.0)  # the stimulus: the silent client's socket and SDK queue fill meanwhile
        before = server.get("/api/state").json()
        got_before, seq_before = len(good.received["/rider/joints"]), follower.frames[-1]["seq"]
        ticks = lambda: server.get("/api/state").json()["counters"]["ticks"]  # noqa: E731
        wait_until(lambda: ticks() >= before["counters"]["ticks"] + 400, 30.0, ticks)  # 2 s of ticks at 200 Hz
        after = server.get("/api/state").json()
        published = after["foxglove"]["rider_messages"] - before["foxglove"]["rider_messages"]
        got = len(good.received["/rider/joints"]) - got_before
        ticks = after["counters"]["ticks"] - before["counters"]["ticks"]
        assert published >= 0.9 * ticks, (published, ticks)  # the sink kept up with the tick
        assert got >= 0.9 * published, (got, published)  # the good client was not held back
        # nor was /ws/rider: the window's ticks all reach it (counted by seq: the follower's
        # thread may parse them a little later on a busy host, but nothing may be missing)
        last = lambda: follower.frames[-1]["seq"]  # noqa: E731
        wait_until(lambda: last() >= seq_before + ticks, 5.0, lambda: (last(), seq_before, ticks))
        window = [f for f in follower.frames if seq_before < f["seq"] <= seq_before + ticks]
        assert len(window) >= 0.9 * ticks, (len(window), ticks)
    finally:
        silent.close()
        good.close()
        follower.close()
