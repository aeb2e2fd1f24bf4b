"""uvicorn's sans-I/O websocket protocol with two additions the live service needs.

- Every connection's kernel send buffer is capped (``SO_SNDBUF``). Linux grows it to
  megabytes: a slow reader would get stale frames, and one that stopped reading would
  be noticed only when the buffer filled (~25 s at 120 Hz). Capped, latest-only is
  real and a stuck client is found within ``publish.send_timeout``.
- ``scope["extensions"]["riderlive.abort"]`` aborts the transport. ASGI has no abort:
  a close frame waits behind data the client never read, and ``transport.close()``
  waits for the buffer to drain, so a cut-off client would otherwise never be freed.
- ``scope["extensions"]["riderlive.transport"]`` is the connection's asyncio transport,
  for the publisher's fast path: a frame from server to client is not masked, so its
  wire bytes are the same for every client with the same subscription; they are
  built once per tick and written to each transport, skipping the per-message ASGI
  and protocol layers (about 30 us each, times 100 clients, times the tick rate).
  Only whole frames are written, from the event loop's thread, like the protocol's
  own writes, so frames never interleave.
"""

from __future__ import annotations

import contextlib
import socket
from typing import Any

from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol

ABORT = "riderlive.abort"
TRANSPORT = "riderlive.transport"


def frame_header(opcode: int, length: int) -> bytes:
    """The header of an unmasked, unfragmented websocket frame (RFC 6455 section 5.2)."""
    if length < 126:
        return bytes((0x80 | opcode, length))
    if length < 1 << 16:
        return bytes((0x80 | opcode, 126)) + length.to_bytes(2, "big")
    return bytes((0x80 | opcode, 127)) + length.to_bytes(8, "big")


def wire_frame(data: str | bytes) -> bytes:
    """A text (str) or binary (bytes) message as the bytes a server puts on the wire."""
    payload = data.encode() if isinstance(data, str) else data
    return frame_header(1 if isinstance(data, str) else 2, len(payload)) + payload


def protocol_class(send_buffer_bytes: int) -> type[WebSocketsSansIOProtocol]:
    """The protocol class for uvicorn's ``ws=`` setting."""

    class RiderWebSocketProtocol(WebSocketsSansIOProtocol):
        def connection_made(self, transport: Any) -> None:
            super().connection_made(transport)
            sock = transport.get_extra_info("socket")
            if sock is not None:
                with contextlib.suppress(OSError):
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, send_buffer_bytes)

        def handle_connect(self, event: Any) -> None:
            super().handle_connect(event)
            scope: Any = getattr(self, "scope", None)
            if scope is not None:
                extensions = scope.setdefault("extensions", {})
                extensions[ABORT] = self.transport.abort
                extensions[TRANSPORT] = self.transport

    return RiderWebSocketProtocol
