"""A client that keeps up gets every tick, even when the web process falls behind (no coalescing)."""

from __future__ import annotations

import json
import os
import signal
import struct
import threading
import time

from websockets.sync.client import connect

from tests.service.live_server import LiveServer
from tests.waiting import Inbox


def test_ticks_that_arrive_together_are_all_sent(server: LiveServer) -> None:
    """SIGSTOP the web process for 0.1 s: the tick goes on, and afterwards every tick it ran is sent.

    (Before, only the newest of the 20 ticks that piled up was sent.) Ticks older than
    ``publish.CATCH_UP`` (0.25 s) when the web process gets to them are skipped and
    counted: a loaded machine may add that much delay of its own, so the count of
    delivered ticks is checked against the ticks run minus those counted.
    """
    arrived: Inbox[int] = Inbox()
    seqs = arrived.items
    with connect(server.ws + "/ws/rider") as ws:
        ws.recv(timeout=5)
        ws.send(json.dumps({"type": "subscribe", "channels": ["head.rz"], "encoding": "binary"}))
        while not isinstance(message := ws.recv(timeout=5), str) or '"subscribed"' not in message:
            pass
        done = threading.Event()

        def read() -> None:
            while not done.is_set():
                message = ws.recv(timeout=5)
                if isinstance(message, bytes):
                    arrived.append(struct.unpack_from("<Q", message, 8)[0])

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        arrived.wait_count(lambda s: True, 60, 10.0)  # streaming (0.3 s of ticks)
        skipped_before = server.metric("riderlive_tick_skipped_total")
        coalesced_before = server.metric("riderlive_ticks_coalesced_total")
        first = seqs[-1]
        os.kill(server.proc.pid, signal.SIGSTOP)
        time.sleep(0.1)  # 20 ticks at 200 Hz pile up in the ring
        os.kill(server.proc.pid, signal.SIGCONT)
        arrived.wait_for(lambda s: s > first + 120, 10.0)  # 0.6 s of ticks after the stall began
        last = seqs[-1]
        skipped = server.metric("riderlive_tick_skipped_total") - skipped_before
        coalesced = server.metric("riderlive_ticks_coalesced_total") - coalesced_before
        done.set()
        reader.join(6)
    window = [s for s in seqs if first <= s <= last]
    assert window == sorted(set(window)), "in order, each once"
    missing = (last - first + 1) - skipped - len(window)
    assert missing <= coalesced < 19, f"{missing} ticks missing, {coalesced} counted as coalesced"
    assert last - first > 100
