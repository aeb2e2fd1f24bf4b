"""Producer clocks against the real server (uvicorn, a real websocket producer, a
``/ws/rider`` follower): a paused clock keeps driving, a clock stepping back is
re-anchored, and neither moves the rider by more per tick than a steady clock does."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable

import numpy as np
from websockets.sync.client import ClientConnection, connect

from riderlive.channels import HORSE_INDEX, RIDER_INDEX
from tests.service.live_server import LiveServer
from tests.service.producers import Follower

RZ = HORSE_INDEX["rearPivot.rz"]
BACK = RIDER_INDEX["lower_back.rz"]
HZ = 120.0


def drive(ws: ClientConnection, seconds: float, clock: Callable[[float], float], segments: list[dict]) -> None:
    """Send a smooth horse (a function of real time) at HZ, stamped with ``clock(elapsed)``;
    collect the segment messages that come back."""
    start = time.perf_counter()
    n = 0
    while (elapsed := time.perf_counter() - start) < seconds:
        rz = 3.0 * math.sin(2.0 * math.pi * 1.5 * elapsed)
        ws.send(json.dumps({"t": clock(elapsed), "values": {"rearPivot.rz": rz}}))
        n += 1
        time.sleep(max(0.0, start + n / HZ - time.perf_counter()))
        try:
            while True:
                message = json.loads(ws.recv(timeout=0))
                if message["type"] == "segment":
                    message["at"] = time.perf_counter()
                    segments.append(message)
        except TimeoutError:
            pass


def largest_step(frames: list[dict]) -> float:
    """The largest change of the rider's lower back between consecutive /ws/rider frames (deg)."""
    back = np.array([f["values"][BACK] for f in frames])
    return float(np.abs(np.diff(back)).max())


def run(server: LiveServer, seconds: float, clock: Callable[[float], float]) -> tuple[list[dict], list[dict]]:
    follower = Follower(server.ws)
    segments: list[dict] = []
    try:
        with connect(server.ws + "/ws/horse") as ws:
            ws.recv(timeout=5)
            drive(ws, 0.5, lambda e: 1000.0 + e, segments)  # settle: driving on a steady clock
            follower.wait_for(lambda f: f["driver"] == "input")
            begin = time.perf_counter()
            drive(ws, seconds, lambda e: clock(e) + 1000.5, segments)
            end = time.perf_counter()
        return [f for f in follower.frames if begin + 0.05 <= f["at"] <= end], segments
    finally:
        follower.close()


def test_a_paused_clock_and_a_stepping_clock_keep_driving_without_jumps(server: LiveServer) -> None:
    baseline, none = run(server, 2.0, lambda e: e)
    assert none == [] and all(f["driver"] == "input" for f in baseline)
    bound = largest_step(baseline)

    paused_before = server.metric("riderlive_clock_jumps_total", 'direction="paused"')
    # the game pauses after 0.5 s for 1.5 s (its clock stands still, frames keep coming), then resumes
    paused, segments = run(server, 3.0, lambda e: min(e, 0.5) + max(0.0, e - 2.0))
    reasons = [s["reason"] for s in segments]
    assert reasons == ["clock_paused", "clock_resumed"], segments
    assert all(f["driver"] == "input" for f in paused), "the producer kept control throughout"
    assert -0.5 <= segments[0]["jump"] < 0.0  # it stood still for less than 0.5 s before the segment
    assert largest_step(paused) <= 1.5 * bound, (largest_step(paused), bound)
    assert server.metric("riderlive_clock_jumps_total", 'direction="paused"') == paused_before + 1

    # 0.2 s back every second (the issue: every 2 s; twice as many steps here)
    stepping, segments = run(server, 3.5, lambda e: e - 0.2 * math.floor(e))
    assert [s["reason"] for s in segments] == ["clock_backward"] * 3, segments
    assert all(abs(s["jump"] + 0.2) < 0.02 for s in segments)
    assert all(f["driver"] == "input" for f in stepping)
    assert largest_step(stepping) <= 1.5 * bound, (largest_step(stepping), bound)
