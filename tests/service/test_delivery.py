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


def test_ticks_that_arrive_together_are_all_sent(server: LiveServer) -> None:
    """SIGSTOP the web process for 0.1 s: the tick goes on, and afterwards every tick it ran is sent.

    (Before, only the newest of the 20 ticks that piled up was sent.) Ticks older than
    ``publish.CATCH_UP`` (0.25 s) when the web process gets to them are skipped and
    counted: a loaded machine may add that much delay of its own, so the count of
    delivered ticks is checked against the ticks run minus those counted.
    """
    seqs: list[int] = []
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
                    seqs.append(struct.unpack_from("<Q", message, 8)[0])

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        time.sleep(0.3)
        skipped_before = server.metric("riderlive_tick_skipped_total")
        coalesced_before = server.metric("riderlive_ticks_coalesced_total")
        first = seqs[-1]
        os.kill(server.proc.pid, signal.SIGSTOP)
        time.sleep(0.1)  # 20 ticks at 200 Hz pile up in the ring
        os.kill(server.proc.pid, signal.SIGCONT)
        time.sleep(0.5)
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
