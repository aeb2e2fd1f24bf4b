"""A Foxglove WebSocket client over ``websockets``, written from the protocol spec
(foxglove/ws-protocol ``docs/spec.md``): JSON ``serverInfo``/``advertise``/``status``,
``subscribe``, binary Message Data (opcode 0x01: u32 subscription id, u64 log time ns,
payload). The SDK's server (0.30) accepts the subprotocol ``foxglove.sdk.v1`` (the
successor of ``foxglove.websocket.v1``, same messages); this client offers both."""

from __future__ import annotations

import base64
import json
import struct
import threading
import time
from collections import defaultdict
from typing import Any

from mcap.records import Schema
from mcap_protobuf.decoder import DecoderFactory
from websockets.sync.client import ClientConnection, connect

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
MESSAGE_DATA = 0x01


class FoxgloveClient:
    """Connects, reads the advertisement, subscribes by topic, collects messages in a thread."""

    def __init__(self, port: int, host: str = "127.0.0.1") -> None:
        self.ws: ClientConnection = connect(f"ws://{host}:{port}", subprotocols=SUBPROTOCOLS, max_size=None)  # type: ignore[list-item]
        self.server_info: dict[str, Any] = {}
        self.channels: dict[str, dict[str, Any]] = {}
        while not (self.server_info and self.channels):
            message = json.loads(self.ws.recv(timeout=5))
            if message["op"] == "serverInfo":
                self.server_info = message
            elif message["op"] == "advertise":
                self.channels.update({c["topic"]: c for c in message["channels"]})
        self.subscriptions: dict[int, str] = {}
        self.received: dict[str, list[tuple[int, bytes, float]]] = defaultdict(list)
        """topic -> (log time ns, payload, arrival perf_counter)."""
        self.status: list[dict[str, Any]] = []
        self.closed = threading.Event()
        threading.Thread(target=self._read, daemon=True).start()

    def subscribe(self, *topics: str, channel_ids: tuple[int, ...] = ()) -> None:
        subs = []
        for topic in topics:
            sub_id = len(self.subscriptions) + 1
            self.subscriptions[sub_id] = topic
            subs.append({"id": sub_id, "channelId": self.channels[topic]["id"]})
        for channel_id in channel_ids:  # channels nobody advertised
            sub_id = len(self.subscriptions) + 1
            self.subscriptions[sub_id] = f"#{channel_id}"
            subs.append({"id": sub_id, "channelId": channel_id})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def _read(self) -> None:
        try:
            for message in self.ws:
                if isinstance(message, bytes):
                    if message[0] == MESSAGE_DATA:
                        sub_id, log_time = struct.unpack_from("<IQ", message, 1)
                        topic = self.subscriptions.get(sub_id, "?")
                        self.received[topic].append((log_time, message[13:], time.perf_counter()))
                else:
                    obj = json.loads(message)
                    if obj.get("op") == "status":
                        self.status.append(obj)
        except Exception:
            pass
        finally:
            self.closed.set()

    def json_messages(self, topic: str) -> list[dict[str, Any]]:
        return [json.loads(data) for _, data, _ in list(self.received[topic])]

    def decoded(self, topic: str) -> list[Any]:
        """Messages of a protobuf channel, decoded with the schema the server advertised."""
        channel = self.channels[topic]
        schema = Schema(id=1, name=channel["schemaName"], encoding="protobuf", data=base64.b64decode(channel["schema"]))
        decode = DecoderFactory().decoder_for("protobuf", schema)
        assert decode is not None
        return [decode(data) for _, data, _ in list(self.received[topic])]

    def close(self) -> None:
        self.ws.close()
