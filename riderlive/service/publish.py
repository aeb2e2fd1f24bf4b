"""``/ws/rider``: fan-out of tick records, latest-only per client, never waiting on one.

The tick's record is encoded once per subscription key (encoding and channel subset)
and, on uvicorn with :mod:`~riderlive.service.wsprotocol`, turned once into wire
bytes that are written straight to each client's transport. A client whose
transport still holds more than one unsent frame is behind: the new frame is dropped
for it (counted), so it gets the newest frame when it catches up and never a
backlog; behind for longer than ``publish.send_timeout``, it is cut off (aborted).

Other messages (hello, status, acknowledgements, errors, goodbye) go through ASGI
from the client's own sender task, with latest-only slots for status and, on other
servers, for frames too. Nothing here waits on a client from the tick's callback,
so a slow client never delays the tick or the others.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import time
from collections import deque
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import orjson
from starlette.websockets import WebSocket, WebSocketDisconnect

from riderlive.channels import RIDER_NAMES, RIDER_PART_NAMES
from riderlive.devices.latch import StopSource
from riderlive.realtime.record import RecordLayout
from riderlive.service import auth
from riderlive.service.codecs import BadFrame, Subscription, decode_ping_id, decode_subscription, parse_message
from riderlive.service.hello import hello, pose_floats
from riderlive.service.rider_frames import encode_frame
from riderlive.service.wsprotocol import ABORT, TRANSPORT, wire_frame
from riderlive.skeleton.rig import Pose

if TYPE_CHECKING:
    from riderlive.service.ports import PublishPort

log = logging.getLogger(__name__)
_ids = itertools.count(1)
CONTROL_QUEUE = 64
CONTROL_BUFFER_LIMIT = 1 << 20
"""A client that neither reads nor stops asking gets no more answers past this backlog."""
CATCH_UP = 0.25
"""Seconds of ticks sent at once after the web process was late (``input.hold``'s default):
older ones are skipped and counted (coalesced), so an overloaded web process sheds work
and its frames stay at most this stale."""


@dataclass(eq=False)
class Subscriber:
    """One /ws/rider client: its subscription, slots and counters."""

    websocket: WebSocket
    id: str
    subscription: Subscription
    phase: int = 0
    """Gets the records whose ``seq % decimation == phase``: clients of one decimation are
    spread over the ticks (``Hub.phase_for``), so each tick writes to a share of them and a
    new input goes out at the next tick, not up to ``decimation`` ticks later."""
    frame: tuple[str | bytes, float] | None = None
    status: str | None = None
    control: deque[str] = field(default_factory=lambda: deque(maxlen=CONTROL_QUEUE))
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    sent: int = 0
    dropped: int = 0
    skipped: int = 0
    """Ticks its decimation wanted that never reached it (skipped by a late tick, coalesced
    after a late web process, lapped in the output ring): with ``sent`` and ``dropped``,
    every wanted tick is counted."""
    first_seq: int | None = None
    """The first tick offered to it since its subscription (or the tick) last changed."""
    last_seq: int | None = None
    """The last tick offered to it (None: none yet, or its subscription changed)."""
    closed: bool = False
    transport: Any = None
    """The raw transport (fast path), or None: frames then go through the slot."""
    behind_since: float | None = None
    controls: bool = False
    """Gave the control token, or none is required (an ``estop`` is latched either way, counted apart)."""

    def offer_frame(self, data: str | bytes, input_rx: float) -> None:
        if self.frame is not None:
            self.dropped += 1
        self.frame = (data, input_rx)
        self.wake.set()

    def offer_status(self, text: str) -> None:
        self.status = text
        self.wake.set()

    def offer_control(self, message: dict[str, Any]) -> None:
        """Acknowledgements, errors, goodbye: in order with the frames around them."""
        text = orjson.dumps(message).decode()
        transport = self.transport
        if transport is None:
            self.control.append(text)
            self.wake.set()
        elif not transport.is_closing() and transport.get_write_buffer_size() < CONTROL_BUFFER_LIMIT:
            transport.write(wire_frame(text))


def abort_transport(websocket: WebSocket) -> None:
    """Drop a stuck connection at once (see :mod:`riderlive.service.wsprotocol`)."""
    abort = websocket.scope.get("extensions", {}).get(ABORT)
    if abort is not None:
        abort()


async def _send(websocket: WebSocket, data: str | bytes) -> None:
    if isinstance(data, bytes):
        await websocket.send_bytes(data)
    else:
        await websocket.send_text(data)


class Hub:
    """The set of /ws/rider clients and the fan-out of tick records."""

    def __init__(self, service: PublishPort) -> None:
        self.service = service
        self.clients: dict[str, Subscriber] = {}
        self._unsent_rx = -1.0
        """Receive time of the newest input taken by a tick but in no frame sent yet (or -1)."""
        self.names: tuple[str, ...] = (*RIDER_NAMES, *service.extra_channels)
        """Published channels: the rider's, the simulated tail and braid (when on), then the rider parts."""
        self.index = {name: i for i, name in enumerate(self.names)}
        parts = set(RIDER_PART_NAMES)  # by subscription only: a client of the rules' channels sees what it saw
        self.default = Subscription(rider=tuple(i for i, n in enumerate(self.names) if n not in parts))

    def hello(self) -> dict[str, Any]:
        return hello(self.service)

    def publish(self, records: list[np.ndarray], now: float | None = None) -> None:
        """Send every one of ``records`` (new ticks, oldest first) that each client's decimation wants.

        A client with decimation N gets every record whose ``seq % N`` is its phase, in order:
        when the web process was late and several ticks arrived at once, a client that
        keeps up still gets all of them (those of the last :data:`CATCH_UP` seconds;
        older ones are counted as coalesced). Each (subscription, record) is encoded
        once. A client that is behind has frames dropped in :meth:`_write`, not here.
        ``now``: ``perf_counter`` seconds (None: the clock's), for the behind clients' timeout.
        """
        metrics = self.service.metrics
        oldest = RecordLayout.engine_t.at(records[-1]) - CATCH_UP if records else 0.0
        if records and RecordLayout.engine_t.at(records[0]) < oldest:
            kept = [r for r in records if RecordLayout.engine_t.at(r) >= oldest]
            metrics.ticks_coalesced += len(records) - len(kept)
            records = kept
        clients = [c for c in self.clients.values() if not c.closed]
        poses = self.service.poses
        now = time.perf_counter() if now is None else now
        timeout = self.service.config.publish.send_timeout
        for record in records:
            seq = RecordLayout.seq.count(record)
            # The newest input not yet in a frame sent: a tick may take one while no client is due.
            unsent_rx = max(self._unsent_rx, RecordLayout.input_rx.at(record))
            encoded: dict[tuple[Any, ...], tuple[str | bytes, bytes]] = {}
            written = offered = False
            for client in clients:
                sub = client.subscription
                if seq % sub.decimation != client.phase:
                    continue
                last = client.last_seq
                if last is not None and seq > last:
                    client.skipped += (seq - last) // sub.decimation - 1
                else:  # the first, or a restarted tick's seq starting again: counted from here
                    client.first_seq = seq
                client.last_seq = seq
                data = encoded.get(sub.key)
                if data is None:
                    bones = np.asarray(poses.rider(record).local_rotations).ravel() if sub.bones else None
                    skeleton_poses = {name: pose_floats(self._pose(name, record)) for name in sub.pose}
                    stamp = self.service.timecode.of_record(record) if sub.timecode else None
                    label = None if stamp is None else (stamp.frames, stamp.label)
                    message = encode_frame(sub, record, bones, skeleton_poses, label)
                    data = encoded[sub.key] = (message, wire_frame(message))
                if client.transport is None:
                    client.offer_frame(data[0], unsent_rx)  # its sender observes the latency
                    offered = True
                else:
                    written |= self._write(client, data[1], now, timeout)
            if unsent_rx >= 0.0 and written:
                metrics.ingest_to_send.observe(self.service.link.engine_time() - unsent_rx)
            self._unsent_rx = -1.0 if written or offered else unsent_rx

    def phase_for(self, client: Subscriber) -> int:
        """The least used phase among the other clients of ``client``'s decimation (lowest on a tie)."""
        decimation = client.subscription.decimation
        used = [0] * decimation
        for other in self.clients.values():
            if other is not client and not other.closed and other.subscription.decimation == decimation:
                used[other.phase % decimation] += 1
        return used.index(min(used))

    def _pose(self, skeleton: str, record: np.ndarray) -> Pose:
        poses = self.service.poses
        return poses.rider(record) if skeleton == "rider" else poses.horse(record)

    def _write(self, client: Subscriber, wire: bytes, now: float, timeout: float) -> bool:
        """The fast path: write a frame's wire bytes (True), or drop it if the client is behind."""
        transport = client.transport
        if client.closed or transport.is_closing():
            client.closed = True
            return False
        if transport.get_write_buffer_size() > len(wire):
            client.dropped += 1
            if client.behind_since is None:
                client.behind_since = now
            elif now - client.behind_since > timeout:
                self.service.metrics.clients_cut_off += 1
                log.warning("client %s has not read for %.1f s: cut off", client.id, timeout)
                client.closed = True
                client.wake.set()
                transport.abort()
            return False
        client.behind_since = None
        transport.write(wire)
        client.sent += 1
        return True

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
                        metrics.ingest_to_send.observe(self.service.link.engine_time() - input_rx)
        except TimeoutError:
            metrics.clients_cut_off += 1
            log.warning("client %s did not read for %.1f s: cut off", client.id, timeout)
            client.closed = True
            asyncio.get_running_loop().create_task(self._close(client, 1013, "too slow"))
        except Exception:  # the client left mid-send
            client.closed = True

    @staticmethod
    async def _close(client: Subscriber, code: int, reason: str) -> None:
        """Close a client that does not read: try a close frame, then drop the connection."""
        with contextlib.suppress(Exception):
            await asyncio.wait_for(client.websocket.close(code=code, reason=reason), 0.5)
        abort_transport(client.websocket)

    async def __call__(self, websocket: WebSocket) -> None:
        service = self.service
        config = service.config
        offered = list(websocket.scope.get("subprotocols", []))
        await websocket.accept(subprotocol=auth.accepted_subprotocol(offered))
        if len(self.clients) >= config.publish.max_clients:
            await websocket.close(code=1013, reason="too many clients")
            return
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
                with contextlib.suppress(Exception):  # it may have left already
                    await websocket.send_json({"type": "error", "reason": "unauthorized", "message": "token required"})
                    await websocket.close(code=4401, reason="unauthorized")
                return
        client = Subscriber(websocket, f"rider-{next(_ids)}", self.default)
        client.transport = websocket.scope.get("extensions", {}).get(TRANSPORT)
        client.controls = not config.token_required or auth.token_matches(
            config.security.token, auth.token_from_subprotocols(offered)
        )
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
                    service.metrics.count_disconnect(message)
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
            if kind == "estop":  # first: latched at once, token or not (never locked: estop_first.py)
                latched = service.supervisor.estop(StopSource.WEBSOCKET)
                service.device_metrics.estops[(StopSource.WEBSOCKET.label, client.controls)] += 1
                if not client.controls:
                    log.warning("e-stop without the control token from websocket client %s: latched", client.id)
                reply = {"type": "estop", "id": obj.get("id"), "latched_at": latched, "authorized": client.controls}
                client.offer_control(reply)
            elif kind == "subscribe":
                client.subscription = decode_subscription(
                    obj, client.subscription, service.config.tick.rate, self.index
                )
                client.phase = self.phase_for(client)
                client.last_seq = None
                client.offer_control(client.subscription.describe(service.config.tick.rate, self.names))
            elif kind == "ping":
                pong = {"type": "pong", "id": decode_ping_id(obj), "engine_time": service.link.engine_time()}
                client.offer_control(pong)
            elif kind == "auth":
                client.controls = client.controls or auth.token_matches(service.config.security.token, obj.get("token"))
            else:
                raise BadFrame("unknown_type", f"unknown message type {str(kind)[:64]!r}")
        except Exception as exc:
            if not isinstance(exc, BadFrame):  # a bug: answered, counted and logged, never a silent drop
                log.exception("publish failed on a message from %s", client.id)
                exc = BadFrame("internal_error", "the service failed on this message (see its log)")
            service.metrics.bad_frames[exc.reason] += 1
            client.offer_control({"type": "error", "reason": exc.reason, "message": str(exc)})

    def snapshot(self) -> list[tuple[str, str, int, int, int]]:
        """Per client: id, path, frames sent, dropped (slot replaced), skipped (never offered)."""
        return [(c.id, "/ws/rider", c.sent, c.dropped, c.skipped) for c in self.clients.values()]

    def describe_clients(self) -> list[dict[str, Any]]:
        """For ``/api/state``: each client's counts (since it connected) and the ticks its
        current subscription covers: from ``first_seq`` to ``last_seq``, every tick its
        decimation wanted was sent, dropped or skipped (+ 1 while a frame waits in its slot)."""
        return [
            {
                "id": c.id,
                "sent": c.sent,
                "dropped": c.dropped,
                "skipped": c.skipped,
                "decimation": c.subscription.decimation,
                "first_seq": c.first_seq,
                "last_seq": c.last_seq,
                "pending": c.frame is not None,
            }
            for c in self.clients.values()
        ]
