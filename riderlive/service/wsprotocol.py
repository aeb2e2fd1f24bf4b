"""uvicorn's sans-I/O websocket protocol with two additions the live service needs.

- Every connection's kernel send buffer is capped (``SO_SNDBUF``). Linux grows it to
  megabytes: a slow reader would get stale frames, and one that stopped reading would
  be noticed only when the buffer filled (~25 s at 120 Hz). Capped, latest-only is
  real and a stuck client is found within ``publish.send_timeout``.
- ``scope["extensions"]["riderlive.abort"]`` aborts the transport. ASGI has no abort:
  a close frame waits behind data the client never read, and ``transport.close()``
  waits for the buffer to drain, so a cut-off client would otherwise never be freed.
"""

from __future__ import annotations

import contextlib
import socket
from typing import Any

from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol

ABORT = "riderlive.abort"


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
                scope.setdefault("extensions", {})[ABORT] = self.transport.abort

    return RiderWebSocketProtocol
