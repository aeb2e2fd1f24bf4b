"""A real OSC receiver on loopback UDP (python-osc's server), grouping messages back into bundles."""

from __future__ import annotations

import socket
import threading
from typing import Any

from pythonosc import dispatcher, osc_server


class VmcReceiver:
    """Listens on 127.0.0.1:port (a free port); ``bundles`` are lists of (address, args)."""

    def __init__(self) -> None:
        self.bundles: list[list[tuple[str, list[Any]]]] = []
        self._want = 0
        self._enough = threading.Event()
        table = dispatcher.Dispatcher()
        table.set_default_handler(self._on_message)
        self.server = osc_server.BlockingOSCUDPServer(("127.0.0.1", 0), table)
        self.port = self.server.server_address[1]
        # Room for a whole burst (a test publishing hundreds of records at once): the kernel's
        # default buffer (~200 KiB) overflows while this thread parses, and loopback UDP then
        # loses datagrams the sender counted as sent.
        force = getattr(socket, "SO_RCVBUFFORCE", None)
        try:
            self.server.socket.setsockopt(socket.SOL_SOCKET, force or socket.SO_RCVBUF, 8 << 20)
        except PermissionError:  # not root: as much as rmem_max allows
            self.server.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
        self._thread = threading.Thread(target=self.server.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
        self._thread.start()

    def _on_message(self, address: str, *args: Any) -> None:
        if address == "/VMC/Ext/OK":  # every bundle starts with OK
            self.bundles.append([])
            if len(self.bundles) >= self._want:
                self._enough.set()
        if self.bundles:
            self.bundles[-1].append((address, list(args)))

    def wait_for(self, count: int, timeout: float = 20.0) -> bool:
        """Until ``count`` bundles have arrived (complete but the last)."""
        self._want = count
        if len(self.bundles) >= count:
            return True
        self._enough.clear()
        return self._enough.wait(timeout) or len(self.bundles) >= count

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()
        self._thread.join(5.0)
