"""``/ws/rider``: every client gets its own sender task and a latest-only frame slot.

The tick's record is encoded once per subscription key (encoding and channel
subset) and offered to each client's slot. The client's sender task sends whatever
is in its slots; a frame still in the slot when the next one arrives is replaced
and counted as dropped. A send that takes longer than ``publish.send_timeout`` cuts
the client off. Nothing here waits on a client from the tick's callback, so a slow
client never delays the tick or the others.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
from collections import deque
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import orjson
from starlette.websockets import WebSocket, WebSocketDisconnect

from riderlive import __version__
from riderlive.channels import AXIS_CONVENTION, HORSE, RIDER
from riderlive.realtime import layout as L
from riderlive.service import auth
from riderlive.service.codecs import (
    PROTOCOL_VERSION,
    BadFrame,
    Subscription,
    decode_subscription,
    encode_frame,
    parse_message,
)

if TYPE_CHECKING:
    from riderlive.service.runtime import Service

log = logging.getLogger(__name__)
_ids = itertools.count(1)
CONTROL_QUEUE = 64


@dataclass(eq=False)
class Subscriber:
    """One /ws/rider client: its subscription, slots and counters."""

    websocket: WebSocket
    id: str
    subscription: Subscription
    frame: tuple[str | bytes, float] | None = None
    status: str | None = None
    control: deque[str] = field(default_factory=lambda: deque(maxlen=CONTROL_QUEUE))
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    sent: int = 0
    dropped: int = 0
    closed: bool = False

    def offer_frame(self, data: str | bytes, input_rx: float) -> None:
        if self.frame is not None:
            self.dropped += 1
        self.frame = (data, input_rx)
        self.wake.set()

    def offer_status(self, text: str) -> None:
        self.status = text
        self.wake.set()

    def offer_control(self, message: dict[str, Any]) -> None:
        self.control.append(orjson.dumps(message).decode())
        self.wake.set()


async def _send(websocket: WebSocket, data: str | bytes) -> None:
    if isinstance(data, bytes):
        await websocket.send_bytes(data)
    else:
        await websocket.send_text(data)


class Hub:
    """The set of /ws/rider clients and the fan-out of tick records."""

    def __init__(self, service: Service) -> None:
        self.service = service
        self.clients: dict[str, Subscriber] = {}
        self._seen_input_rx = -1.0

    def hello(self) -> dict[str, Any]:
        service = self.service
        config = service.config
        return {
            "type": "hello",
            "protocol": PROTOCOL_VERSION,
            "server": f"riderlive {__version__}",
            "session": service.session,
            "tick_rate": config.tick.rate,
            "engine_time": service.link.engine_time(),
            "channels": [{"name": c.name, "unit": c.unit, "meaning": c.meaning} for c in RIDER],
            "horse_channels": [{"name": c.name, "unit": c.unit, "meaning": c.meaning} for c in HORSE],
            "axis_convention": AXIS_CONVENTION,
            "length_scale": config.tick.length_scale,
            "length_unit": "service length unit: thesis rig units / length_scale",
            "rotation_unit": "deg",
            "encodings": ["json", "binary"],
            "drivers": ["procedural", "input", "neutral"],
        }

    def publish(self, record: np.ndarray) -> None:
        """Offer one tick record to every client whose decimation wants it."""
        seq = int(record[L.OUT_SEQ])
        input_rx = float(record[L.OUT_INPUT_RX])
        if input_rx <= self._seen_input_rx:
            input_rx = -1.0
        else:
            self._seen_input_rx = input_rx
        encoded: dict[tuple[Any, ...], str | bytes] = {}
        for client in self.clients.values():
            sub = client.subscription
            if client.closed or seq % sub.decimation:
                continue
            data = encoded.get(sub.key)
            if data is None:
                data = encode_frame(sub, record)
                encoded[sub.key] = data
            client.offer_frame(data, input_rx)

    def publish_status(self, status: dict[str, Any]) -> None:
        text = orjson.dumps({"type": "status", **status}).decode()
        for client in self.clients.values():
            client.offer_status(text)

    async def goodbye(self, reason: str) -> None:
        """Tell every client the service is going away, then close them."""
        for client in list(self.clients.values()):
            client.offer_control({"type": "goodbye", "reason": reason})
        await asyncio.sleep(0.05)
        for client in list(self.clients.values()):
            client.closed = True
            client.wake.set()
            with contextlib.suppress(Exception):  # already gone or not reading
                await asyncio.wait_for(client.websocket.close(code=1001, reason=reason), 0.5)

    async def sender(self, client: Subscriber) -> None:
        """Send the client's slots until it leaves, is cut off or the service stops."""
        timeout = self.service.config.publish.send_timeout
        metrics = self.service.metrics
        try:
            while not client.closed:
                await client.wake.wait()
                client.wake.clear()
                while client.control:
                    await asyncio.wait_for(_send(client.websocket, client.control.popleft()), timeout)
                if client.status is not None:
                    status, client.status = client.status, None
                    await asyncio.wait_for(_send(client.websocket, status), timeout)
                if client.frame is not None and not client.closed:
                    (data, input_rx), client.frame = client.frame, None
                    await asyncio.wait_for(_send(client.websocket, data), timeout)
                    client.sent += 1
                    if input_rx >= 0.0:
                        metrics.input_to_send.observe(self.service.link.engine_time() - input_rx)
        except TimeoutError:
            metrics.clients_cut_off += 1
            log.warning("client %s did not read for %.1f s: cut off", client.id, timeout)
            client.closed = True
            asyncio.get_running_loop().create_task(self._close(client, 1013, "too slow"))
        except Exception:  # the client left mid-send
            client.closed = True

    @staticmethod
    async def _close(client: Subscriber, code: int, reason: str) -> None:
        with contextlib.suppress(Exception):  # a stuck transport is dropped by the close timeout
            await asyncio.wait_for(client.websocket.close(code=code, reason=reason), 1.0)

    async def __call__(self, websocket: WebSocket) -> None:
        service = self.service
        config = service.config
        offered = auth.subprotocols(websocket.headers.get("sec-websocket-protocol"))
        if len(self.clients) >= config.publish.max_clients:
            await websocket.close(code=1013, reason="too many clients")
            return
        await websocket.accept(subprotocol=auth.accepted_subprotocol(offered))
        if config.security.publish_requires_token and not auth.token_matches(
            config.security.token, auth.token_from_subprotocols(offered)
        ):
            try:
                first = await asyncio.wait_for(websocket.receive_text(), 5.0)
                token = orjson.loads(first).get("token")
            except Exception:
                token = None
            if not auth.token_matches(config.security.token, token):
                service.metrics.bad_frames["unauthorized"] += 1
                await websocket.send_json({"type": "error", "reason": "unauthorized", "message": "token required"})
                await websocket.close(code=4401, reason="unauthorized")
                return
        client = Subscriber(websocket, f"rider-{next(_ids)}", Subscription())
        await websocket.send_text(orjson.dumps(self.hello()).decode())
        status = service.link.status()
        if status:
            client.offer_status(orjson.dumps({"type": "status", **status}).decode())
        self.clients[client.id] = client
        task = asyncio.get_running_loop().create_task(self.sender(client))
        try:
            while not client.closed:
                message = await websocket.receive()
                if message["type"] == "websocket.disconnect":
                    break
                self.handle(client, message.get("text") or message.get("bytes") or b"")
        except (WebSocketDisconnect, RuntimeError):
            pass
        finally:
            client.closed = True
            client.wake.set()
            self.clients.pop(client.id, None)
            task.cancel()

    def handle(self, client: Subscriber, data: str | bytes) -> None:
        service = self.service
        try:
            obj = parse_message(data, service.config.input.max_message_bytes)
            kind = obj.get("type")
            if kind == "subscribe":
                client.subscription = decode_subscription(obj, client.subscription, service.config.tick.rate)
                client.offer_control(client.subscription.describe(service.config.tick.rate))
            elif kind == "ping":
                client.offer_control({"type": "pong", "id": obj.get("id"), "engine_time": service.link.engine_time()})
            elif kind == "auth":
                pass
            else:
                raise BadFrame("unknown_type", f"unknown message type {kind!r}")
        except BadFrame as exc:
            service.metrics.bad_frames[exc.reason] += 1
            client.offer_control({"type": "error", "reason": exc.reason, "message": str(exc)})

    def snapshot(self) -> list[tuple[str, str, int, int]]:
        return [(c.id, "/ws/rider", c.sent, c.dropped) for c in self.clients.values()]
