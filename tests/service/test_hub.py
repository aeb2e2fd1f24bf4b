"""The /ws/rider fan-out in process: the real Hub on fake transports, a fake tick port and a
virtual clock (no server, no sleeps). Over real websockets: tests/service/test_publish.py,
test_slow_client.py, test_delivery.py."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np
import pytest
from starlette.websockets import WebSocket

from riderlive.channels import RIDER_NAMES, RIDER_PART_NAMES
from riderlive.devices.latch import StopSource
from riderlive.realtime.record import RecordLayout
from riderlive.service.codecs import Subscription
from riderlive.service.publish import CATCH_UP, Hub, Subscriber
from riderlive.service.rider_frames import decode_binary_frame
from riderlive.service.wsprotocol import wire_frame
from tests.service.fakes import FakeService

WIDTH = RecordLayout.rider.stop + len(RIDER_PART_NAMES)


@dataclass
class FakeTransport:
    """An asyncio transport as the hub's fast path uses it; ``backlog``: bytes not yet on the wire."""

    backlog: int = 0
    written: list[bytes] = field(default_factory=list)
    aborted: bool = False

    def is_closing(self) -> bool:
        return self.aborted

    def get_write_buffer_size(self) -> int:
        return self.backlog

    def write(self, data: bytes) -> None:
        self.written.append(data)

    def abort(self) -> None:
        self.aborted = True


def record(seq: int, engine_t: float, input_rx: float = -1.0) -> np.ndarray:
    out = np.zeros(WIDTH)
    out[RecordLayout.seq.start], out[RecordLayout.engine_t.start], out[RecordLayout.input_rx.start] = (
        seq,
        engine_t,
        input_rx,
    )
    out[RecordLayout.rider.slice] = np.arange(len(RIDER_NAMES)) + seq / 1000.0
    return out


def client(hub: Hub, name: str, sub: Subscription | None = None, *, controls: bool = False) -> Subscriber:
    c = Subscriber(cast(WebSocket, None), name, sub or hub.default, controls=controls)
    c.transport = FakeTransport()
    c.phase = hub.phase_for(c)
    hub.clients[name] = c
    return c


def transport(c: Subscriber) -> FakeTransport:
    return cast(FakeTransport, c.transport)


def payload(wire: bytes) -> bytes:
    """The message of one unmasked server frame (RFC 6455 section 5.2)."""
    size = wire[1] & 0x7F
    start = 2 if size < 126 else 4 if size == 126 else 10
    return wire[start:]


def messages(c: Subscriber) -> list[dict[str, Any]]:
    return [json.loads(payload(w)) for w in transport(c).written]


def test_each_subscription_is_encoded_once_and_every_due_client_gets_it_in_order() -> None:
    service = FakeService()
    hub = Hub(service)
    a, b = client(hub, "a"), client(hub, "b")
    binary = client(hub, "bin", Subscription(rider=(0, 1), encoding="binary"))
    hub.publish([record(1, 0.01), record(2, 0.02)], now=service.clock.now)
    assert [len(transport(c).written) for c in (a, b, binary)] == [2, 2, 2]
    assert transport(a).written[0] is transport(b).written[0]  # one encoding, one wire form, shared
    text = payload(transport(a).written[1]).decode()
    assert transport(a).written[1] == wire_frame(text)
    frame = json.loads(text)
    assert frame["seq"] == 2 and len(frame["values"]) == len(RIDER_NAMES)  # the rider parts by subscription only
    assert frame["values"][3] == pytest.approx(3.002)
    decoded = decode_binary_frame(payload(transport(binary).written[0]))
    assert decoded["seq"] == 1 and decoded["values"] == pytest.approx([0.001, 1.001])
    assert a.sent == b.sent == 2 and a.dropped == 0


def test_decimated_clients_are_spread_over_the_ticks() -> None:
    hub = Hub(FakeService())
    every_other = [client(hub, f"d{i}", Subscription(rider=(0,), decimation=2)) for i in range(2)]
    assert [c.phase for c in every_other] == [0, 1]
    hub.publish([record(s, s / 100) for s in range(1, 7)])
    seqs = [[m["seq"] for m in messages(c)] for c in every_other]
    assert seqs == [[2, 4, 6], [1, 3, 5]]


def test_a_client_that_falls_behind_gets_no_backlog_and_is_cut_off_after_the_timeout() -> None:
    service = FakeService()
    clock = service.clock
    hub = Hub(service)
    slow, fast = client(hub, "slow"), client(hub, "fast")
    transport(slow).backlog = 1 << 20  # its kernel buffer is full: it does not read
    timeout = service.config.publish.send_timeout
    hub.publish([record(1, 0.01)], now=clock.now)
    assert slow.dropped == 1 and slow.behind_since == clock.now and not transport(slow).aborted
    hub.publish([record(2, 0.02)], now=clock.advance(timeout))  # behind for exactly the timeout: kept
    assert not slow.closed and slow.dropped == 2
    hub.publish([record(3, 0.03)], now=clock.advance(1e-3))
    assert slow.closed and transport(slow).aborted and service.metrics.clients_cut_off == 1
    assert len(transport(fast).written) == 3 and fast.dropped == 0  # the others never wait on it
    hub.publish([record(4, 0.04)], now=clock.advance(0.01))
    assert len(transport(slow).written) == 0 and slow.dropped == 3  # closed: not even counted again


def test_a_client_that_catches_up_is_no_longer_behind() -> None:
    service = FakeService()
    hub = Hub(service)
    c = client(hub, "c")
    transport(c).backlog = 1 << 20
    hub.publish([record(1, 0.01)], now=service.clock.now)
    transport(c).backlog = 0
    hub.publish([record(2, 0.02)], now=service.clock.advance(100.0))
    assert c.behind_since is None and not c.closed and c.sent == 1


def test_a_late_web_process_sends_only_the_last_catch_up_seconds() -> None:
    service = FakeService()
    hub = Hub(service)
    c = client(hub, "c")
    records = [record(s, s * 0.01) for s in range(1, 101)]  # a second of ticks at once
    hub.publish(records)
    kept = [m["seq"] for m in messages(c)]
    newest = records[-1][RecordLayout.engine_t.start]
    assert kept == [s for s in range(1, 101) if s * 0.01 >= newest - CATCH_UP]
    assert service.metrics.ticks_coalesced == 100 - len(kept)


def test_ingest_to_send_is_measured_on_the_tick_ports_clock() -> None:
    service = FakeService()
    hub = Hub(service)
    client(hub, "c", Subscription(rider=(0,), decimation=2))  # due on even ticks only
    service.clock.advance(2.0)  # engine time 2.0
    hub.publish([record(1, 1.99, input_rx=1.995)])  # taken by a tick no client is due at
    assert service.metrics.ingest_to_send.count == 0
    hub.publish([record(2, 2.0)])
    assert service.metrics.ingest_to_send.count == 1
    assert service.metrics.ingest_to_send.snapshot().total == pytest.approx(0.005)  # 2.0 - 1.995


def test_control_messages_subscribe_ping_and_estop() -> None:
    service = FakeService()
    hub = Hub(service)
    viewer, operator = client(hub, "viewer"), client(hub, "operator", controls=True)
    hub.handle(viewer, json.dumps({"type": "subscribe", "channels": ["lower_back.rz"], "rate": 60}))
    subscribed = messages(viewer)[-1]
    assert subscribed["type"] == "subscribed" and subscribed["channels"] == ["lower_back.rz"]
    assert subscribed["decimation"] == 2 and viewer.subscription.decimation == 2
    service.clock.advance(4.5)
    hub.handle(viewer, json.dumps({"type": "ping", "id": 7}))
    assert messages(viewer)[-1] == {"type": "pong", "id": 7, "engine_time": 4.5}
    hub.handle(viewer, json.dumps({"type": "estop", "id": 1}))  # never locked: latched without the token
    unlocked = messages(viewer)[-1]
    assert unlocked["type"] == "estop" and unlocked["id"] == 1 and unlocked["authorized"] is False
    assert service.supervisor.requests == [StopSource.WEBSOCKET]
    hub.handle(operator, json.dumps({"type": "estop", "id": 2}))
    assert service.supervisor.requests == [StopSource.WEBSOCKET] * 2
    assert messages(operator)[-1]["type"] == "estop" and messages(operator)[-1]["authorized"] is True
    assert service.device_metrics.estops == {("websocket", False): 1, ("websocket", True): 1}
    hub.handle(viewer, b"\xff")
    assert service.metrics.bad_frames["unauthorized"] == 0 and sum(service.metrics.bad_frames.values()) == 1


def test_the_hello_describes_the_service_through_its_ports() -> None:
    service = FakeService()
    hello = Hub(service).hello()
    assert hello["session"] == "test-session" and hello["tick_rate"] == service.config.tick.rate
    assert hello["length_unit"] == "m" and hello["saddle"]["point"] == {"forward": 0.6, "up": 0.15, "unit": "m"}
    assert [c["name"] for c in hello["channels"]] == list(RIDER_NAMES)
