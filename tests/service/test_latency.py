"""Latency through the real service: a producer's frames to the clients and to a rig's bus.

The real server, the real dynamixel-sdk on the emulated bus (``test_rig_hookup``'s
fixture), a producer on ``/ws/horse`` and a reader on ``/ws/rider``. Checked: every
input taken gets one ingest-to-send and (while the rig runs) one ingest-to-wire
observation; both are positive and bounded by what a tick can add; ``/api/latency``
and ``/metrics`` report the same counts; the page's panel reads the same answer
(``tests/web``). Figures, not tested here (the machine may be saturated):
``bench/bench_service.py``.
"""

from __future__ import annotations

import threading
import time

import msgpack
from websockets.sync.client import connect

from tests.service.live_server import LiveServer
from tests.service.test_rig_hookup import AUTH, post, rig_server, wait_state

__all__ = ["rig_server"]
RATE = 100.0
"""The fixture's tick rate."""


def stream(live: LiveServer, seconds: float, rate: float = 60.0) -> int:
    """Horse frames into /ws/horse at ``rate`` while a reader drains /ws/rider; returns frames sent."""
    stop = threading.Event()

    def read() -> None:
        with connect(live.ws + "/ws/rider") as ws:
            while not stop.is_set():
                ws.recv(timeout=2.0)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    sent = 0
    with connect(live.ws + "/ws/horse") as ws:
        ws.recv(timeout=10.0)  # welcome
        t0 = time.perf_counter()
        while (t := time.perf_counter() - t0) < seconds:
            ws.send(msgpack.packb({"t": t, "values": {"rearPivot.rz": 2.0 * (t % 1.0), "lfHoof.ty": 0.1}}))
            sent += 1
            time.sleep(max(0.0, t0 + sent / rate - time.perf_counter()))
    stop.set()
    reader.join(5.0)
    return sent


def latency(live: LiveServer) -> dict:
    answer = live.get("/api/latency", params={"buckets": "true"}, headers=AUTH)
    assert answer.status_code == 200, answer.text
    return answer.json()


def test_ingest_to_send_and_to_wire_are_observed_once_per_input(rig_server: LiveServer) -> None:
    live = rig_server
    wait_state(live, "disarmed")
    idle = latency(live)["histograms"]
    assert idle["ingest_to_wire"]["total"]["count"] == 0  # disarmed: no goal is written
    assert post(live, "/api/arm", {"device": "bench3"}).status_code == 200
    wait_state(live, "running")
    sent = stream(live, 1.5)
    answer = latency(live)
    assert answer["goal"] == 1.0 / RATE + 0.001
    taken = live.get("/api/state", headers=AUTH).json()["counters"]["input_frames"]
    for name in ("ingest_to_send", "ingest_to_wire"):
        total = answer["histograms"][name]["total"]
        # One observation per tick that took new input: at most one per input frame, and
        # at least one per tick period in which frames arrived (60 Hz into a 100 Hz tick).
        assert 0.5 * sent <= total["count"] <= taken <= sent, (name, total, sent, taken)
        assert 0.0 < total["p50"] <= total["p99"] <= total["max"] * 1.023
        assert total["max"] < 5.0  # seconds: a stuck pipeline would show here
        counts = answer["histograms"][name]["buckets"]
        assert sum(counts.values()) == total["count"]
        metric = f"riderlive_{name}_seconds_count"
        assert live.metric(metric) >= total["count"]
    # A frame cannot reach the wire before a tick took it, nor be sent before it was taken.
    lateness = answer["histograms"]["tick_lateness"]["total"]
    assert lateness["count"] > RATE  # every tick
    text = live.get("/metrics").text
    for name in ("tick_lateness", "ingest_to_send", "ingest_to_wire"):
        assert f"# TYPE riderlive_{name}_seconds histogram" in text
    assert 'riderlive_ingest_to_wire_seconds_bucket{le="+Inf"}' in text
    window = latency(live)["histograms"]["ingest_to_send"]["window"]
    assert window["count"] <= answer["histograms"]["ingest_to_send"]["total"]["count"]


def test_clients_of_one_decimation_are_spread_over_the_ticks() -> None:
    from types import SimpleNamespace
    from typing import Any, cast

    from riderlive.service.codecs import Subscription
    from riderlive.service.publish import Hub, Subscriber

    hub = Hub(cast(Any, SimpleNamespace(extra_channels=())))
    phases = []
    for i in range(10):
        client = Subscriber(cast(Any, None), f"c{i}", Subscription(rider=(0,), decimation=4))
        client.phase = hub.phase_for(client)
        hub.clients[client.id] = client
        phases.append(client.phase)
    assert phases == [0, 1, 2, 3, 0, 1, 2, 3, 0, 1]
    hub.clients["c1"].closed = True  # a gone client frees its phase
    newcomer = Subscriber(cast(Any, None), "n", Subscription(rider=(0,), decimation=4))
    assert hub.phase_for(newcomer) == 1
    single = Subscriber(cast(Any, None), "s", Subscription(rider=(0,), decimation=3))
    assert hub.phase_for(single) == 0  # alone at its decimation: seq % 3 == 0, as before
