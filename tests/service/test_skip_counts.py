"""Every tick a /ws/rider client's decimation wants is sent, dropped or counted as skipped,
against the real server with its web process stopped past the catch-up window."""

from __future__ import annotations

import json
import os
import signal
import struct
import threading
import time

from websockets.sync.client import connect

from tests.service.live_server import LiveServer
from tests.waiting import wait_until


def test_sent_dropped_and_skipped_cover_every_wanted_tick(server: LiveServer) -> None:
    seqs: list[int] = []
    with connect(server.ws + "/ws/rider") as ws:
        ws.recv(timeout=5)
        ws.send(json.dumps({"type": "subscribe", "channels": ["head.rz"], "rate": 100, "encoding": "binary"}))
        early: list[int] = []  # frames of the default subscription, sent before the ack (in order with it)
        while (obj := json.loads(ws.recv(timeout=5)))["type"] != "subscribed":
            if obj["type"] == "frame":
                early.append(obj["seq"])
        done = threading.Event()

        def read() -> None:
            while not done.is_set():
                message = ws.recv(timeout=5)
                if isinstance(message, bytes):
                    seqs.append(struct.unpack_from("<Q", message, 8)[0])

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        wait_until(lambda: len(seqs) >= 30, 10.0, lambda: len(seqs))  # streaming at 100 Hz
        os.kill(server.proc.pid, signal.SIGSTOP)
        time.sleep(0.5)  # the stimulus, 100 ticks at 200 Hz: those older than publish.CATCH_UP (0.25 s) are skipped
        os.kill(server.proc.pid, signal.SIGCONT)
        resumed = len(seqs)
        wait_until(lambda: len(seqs) >= resumed + 30, 10.0, lambda: len(seqs))  # streaming again
        clients = server.get("/api/state").json()["clients"]
        done.set()
        reader.join(6)
    (ours,) = [c for c in clients if c["decimation"] == 2]
    wanted = (ours["last_seq"] - ours["first_seq"]) // 2 + 1  # since the subscription
    # the counts are since the client connected: take out those of the default subscription
    # (every tick; a gap between two of its frames is skipped ticks: the tick's own or coalesced)
    before = len(early)
    skipped_before = sum(b - a - 1 for a, b in zip(early, early[1:]))
    counted = ours["sent"] - before + ours["dropped"] + ours["skipped"] - skipped_before + int(ours["pending"])
    assert counted == wanted, (ours, early)
    assert ours["skipped"] - skipped_before >= 10, "the ticks older than the catch-up window"  # ~25 at 200 Hz / 2
    # the reader runs on past the state read (the frame it waits for when told to stop): every
    # frame it got up to last_seq was sent (or pending) by then; the early ones were text, not here
    assert len(set(seqs)) == len(seqs), "no frame twice"
    received = sum(s <= ours["last_seq"] for s in seqs)
    assert received <= ours["sent"] - before + int(ours["pending"]), (received, ours, early)
    assert all(s % 2 == ours["first_seq"] % 2 for s in seqs), "one phase"
