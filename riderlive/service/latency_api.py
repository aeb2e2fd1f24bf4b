"""``GET /api/latency``: the live latency histograms, summarised over a recent window.

Three histograms (:mod:`riderlive.realtime.latency`, seconds):

- ``tick_lateness``: how late each tick woke after its deadline (the tick process);
- ``ingest_to_send``: a horse frame decoded by the web process to the first rider
  frame computed from it written to every client due that tick (the web process);
- ``ingest_to_wire``: the same frame to the first device goal computed from it handed
  to the device's port (the tick process; only with a device that is moving);
- ``ingest_to_tick``: the same frame to the deadline of the tick that took it (the
  tick process): the wait for the tick, which the phase lock shortens.

The answer has each one's ``window`` (about the last ``window`` seconds, default 10:
what the page shows), its ``total`` since the service started, and with
``buckets=true`` the total's non-empty buckets (``{index: count}``, bounds in
``bounds``) so that a client can subtract two answers and take exact quantiles of
any span (``bench/bench_service.py`` does). ``goal`` is the issue-18 target, one tick
period + 1 ms. ``phase_lock`` is the tick's phase lock (None when off): ``locked``,
``lead`` and ``margin`` in seconds (None: no phase known), ``resultant``, ``slews``.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Sequence
from typing import Any

import numpy as np
from fastapi import FastAPI, Query
from fastapi.params import Depends

from riderlive.realtime import latency
from riderlive.realtime.latency import LatencySnapshot
from riderlive.service.runtime import Service

HISTORY_S = 120.0
"""Snapshots older than this are forgotten (the longest window an answer can cover)."""


class LatencyHistory:
    """Snapshots taken when asked, so that an answer can cover roughly the last ``window`` seconds."""

    def __init__(self) -> None:
        self.snapshots: deque[tuple[float, dict[str, LatencySnapshot]]] = deque(maxlen=512)

    def window(self, now: float, current: dict[str, LatencySnapshot], seconds: float) -> tuple[float, dict[str, Any]]:
        """(seconds covered, name -> summary) since the newest snapshot at least ``seconds`` old."""
        while self.snapshots and now - self.snapshots[0][0] > HISTORY_S:
            self.snapshots.popleft()
        base_t, base = now, None
        for t, snapshot in self.snapshots:
            if now - t >= seconds:
                base_t, base = t, snapshot
            else:
                break
        if base is None and self.snapshots:
            base_t, base = self.snapshots[0]
        self.snapshots.append((now, current))
        out = {}
        for name, snap in current.items():
            window = snap.since(base[name]) if base is not None and name in base else snap
            out[name] = window.summary()
        return now - base_t, out


def sparse(buckets: np.ndarray) -> dict[str, int]:
    return {str(i): int(c) for i, c in enumerate(buckets) if c}


def phase_lock(service: Service) -> dict[str, Any] | None:
    """The tick's phase lock from its counters (None when ``tick.phase_lock`` is off)."""
    if not service.config.tick.phase_lock:
        return None
    counters = service.link.counters.snapshot()

    def seconds(key: str) -> float | None:
        value = counters.get(key, -1.0)
        return None if value < 0.0 else value

    return {
        "locked": counters.get("phase_locked", 0.0) > 0.0,
        "lead": seconds("phase_lead"),
        "margin": seconds("phase_margin"),
        "resultant": counters.get("phase_resultant", 0.0),
        "slews": int(counters.get("phase_slews", 0)),
    }


def add_latency_routes(app: FastAPI, service: Service, dependencies: Sequence[Depends]) -> None:
    history = LatencyHistory()

    @app.get("/api/latency", dependencies=list(dependencies), summary="Latency histograms: tick, ingest to send/wire")
    async def get_latency(window: float = Query(10.0, ge=1.0, le=HISTORY_S), buckets: bool = False) -> dict[str, Any]:
        current = service.latency()
        covered, windows = history.window(time.perf_counter(), current, window)
        period = 1.0 / service.config.tick.rate
        answer: dict[str, Any] = {
            "tick_period": period,
            "goal": period + 0.001,
            "window_seconds": covered,
            "histograms": {name: {"window": windows[name], "total": snap.summary()} for name, snap in current.items()},
            "phase_lock": phase_lock(service),
        }
        if buckets:
            answer["bounds"] = list(latency.BOUNDS)
            for name, snap in current.items():
                answer["histograms"][name]["buckets"] = sparse(snap.buckets)
                answer["histograms"][name]["sum"] = snap.total
        return answer
