"""Producer clocks against the real server (uvicorn, a real websocket producer, a
``/ws/rider`` follower): a paused clock keeps driving, a clock stepping back is
re-anchored, and neither moves the rider by more per tick than a steady clock does."""

from __future__ import annotations

import bisect
import json
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from websockets.sync.client import ClientConnection, connect

from riderlive.channels import HORSE_INDEX, RIDER_INDEX
from riderlive.service.clocks import STEP_S
from tests.service.live_server import LiveServer
from tests.service.producers import Follower

RZ = HORSE_INDEX["rearPivot.rz"]
BACK = RIDER_INDEX["lower_back.rz"]
HZ = 120.0


def horse(t: float) -> float:
    return 3.0 * math.sin(2.0 * math.pi * 1.5 * t)


def horse_frame(t: float, at: float) -> dict[str, Any]:
    """A /ws/horse frame stamped ``t`` showing the horse at time ``at``."""
    return {"t": t, "values": {"rearPivot.rz": horse(at)}}


def drive(
    ws: ClientConnection,
    seconds: float,
    clock: Callable[[float], float],
    segments: list[dict],
    game: bool,
    stamps: list[float],
    sent: list[float] | None = None,
    make: Callable[[float, float], dict[str, Any]] = horse_frame,
) -> None:
    """Send a smooth horse (or ``make(stamp, time shown)``'s frames) at HZ, stamped with
    ``clock(elapsed)``: a function of that clock (``game``: a game's pose follows its clock,
    and stands still with it) or of real time (a producer whose timestamps alone step);
    collect the segment messages that come back and the stamps sent (``stamps``, in order;
    ``sent``: when each send began, perf_counter s)."""
    start = time.perf_counter()
    n = 0
    while (elapsed := time.perf_counter() - start) < seconds:
        t = clock(elapsed)
        if sent is not None:
            sent.append(time.perf_counter())  # before the send: no frame can arrive before it
        ws.send(json.dumps(make(t, t if game else elapsed)))
        stamps.append(t)
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


def drivers(frames: list[dict]) -> list[tuple[str, int, float]]:
    """Runs of the same driver: (driver, frames, source time at its start), for messages."""
    runs: list[tuple[str, int, float]] = []
    for f in frames:
        if runs and runs[-1][0] == f["driver"]:
            runs[-1] = (runs[-1][0], runs[-1][1] + 1, runs[-1][2])
        else:
            runs.append((f["driver"], 1, f["source_t"]))
    return runs


def largest_step(frames: list[dict]) -> float:
    """The largest change of the rider's lower back per tick between consecutive /ws/rider
    frames (deg; a frame the follower missed makes a two-tick step, counted as two)."""
    back = np.array([f["values"][BACK] for f in frames])
    seq = np.array([f["seq"] for f in frames])
    return float((np.abs(np.diff(back)) / np.diff(seq)).max())


def steps_back(stamps: list[float]) -> list[tuple[float, float]]:
    """(previous, t) of each frame sent stamped more than clocks.STEP_S before the one before
    it. A sender late by more than the step across it (a loaded host) sends none there: its
    stamps only slow down, and the service has no step to see."""
    return [(a, b) for a, b in zip(stamps, stamps[1:]) if b < a - STEP_S]


def run(
    server: LiveServer,
    seconds: float,
    clock: Callable[[float], float],
    game: bool,
    sent: list[float] | None = None,
    *,
    path: str = "/ws/horse",
    make: Callable[[float, float], dict[str, Any]] = horse_frame,
    settle: float = 0.5,
    before_close: Callable[[list[float]], None] | None = None,
) -> tuple[list[dict], list[dict], list[float]]:
    """``settle`` s on a steady clock, then ``seconds`` on ``clock``, without a break in the
    stream to ``path``; the follower's frames of the second part, the segment messages and
    the stamps sent (``sent``: when each was sent). ``before_close(stamps)`` runs after the
    last send, while the producer is still connected."""
    follower = Follower(server.ws)
    segments: list[dict] = []
    stamps: list[float] = []
    try:
        with connect(server.ws + path) as ws:
            ws.recv(timeout=5)
            begin = time.perf_counter() + settle
            drive(
                ws,
                settle + seconds,
                lambda e: 1000.0 + e if e < settle else 1000.0 + settle + clock(e - settle),
                segments,
                game,
                stamps,
                sent,
                make,
            )
            end = time.perf_counter()
            if before_close is not None:
                before_close(stamps)
        frames = [f for f in follower.frames if begin + 0.05 <= f["at"] <= end]
        assert frames and any(f["driver"] == "input" for f in follower.frames if f["at"] < begin), "it drove at once"
        return frames, segments, stamps
    finally:
        follower.close()


def test_a_paused_clock_and_a_stepping_clock_keep_driving_without_jumps(server: LiveServer) -> None:
    baseline, none, _ = run(server, 2.0, lambda e: e, game=True)
    assert none == [] and all(f["driver"] == "input" for f in baseline)
    bound = largest_step(baseline)

    paused_before = server.metric("riderlive_clock_jumps_total", 'direction="paused"')
    # the game pauses after 0.5 s for 1.5 s (its clock stands still, frames keep coming), then resumes
    paused, segments, _ = run(server, 3.0, lambda e: min(e, 0.5) + max(0.0, e - 2.0), game=True)
    reasons = [s["reason"] for s in segments]
    assert reasons == ["clock_paused", "clock_resumed"], segments
    assert all(f["driver"] == "input" for f in paused), ("the producer kept control throughout", drivers(paused))
    assert -0.5 <= segments[0]["jump"] < 0.0  # it stood still for less than 0.5 s before the segment
    assert largest_step(paused) <= 1.5 * bound, (largest_step(paused), bound)
    assert server.metric("riderlive_clock_jumps_total", 'direction="paused"') == paused_before + 1

    # 0.2 s back every second (the issue: every 2 s; twice as many steps here)
    stepping, segments, stamps = run(server, 3.5, lambda e: e - 0.2 * math.floor(e), game=False)
    sent = steps_back(stamps)
    # 3 steps sent, unless the sender was late across one (seen once in a full suite on a loaded host)
    assert len(sent) >= 2, ("the sender was late across more than one step", sent)
    # each step sent is one segment, told with the two stamps around it
    assert [s["reason"] for s in segments] == ["clock_backward"] * len(sent), (segments, sent)
    assert [(s["previous_t"], s["t"]) for s in segments] == sent, (segments, sent)
    # the step is 0.2 s less the time between the two frames (8 ms at 120 Hz, more when the
    # sender is late: by 0.15 s, -0.05 s; the two stamps are checked exactly above)
    assert all(s["jump"] == s["t"] - s["previous_t"] and -0.2 < s["jump"] < 0.0 for s in segments), segments
    assert all(f["driver"] == "input" for f in stepping)
    assert largest_step(stepping) <= 1.5 * bound, (largest_step(stepping), bound)


def held_and_late(frames: list[dict], stamps: list[float], sent: list[float]) -> tuple[float, np.ndarray]:
    """Of the frames from 1.5 s on (the clock's rate estimated): the share that held the newest
    frame (a frame's ``source_t`` is a stamp itself: not interpolated), and each one's
    lateness (the newest stamp whose send began before the frame arrived minus its
    ``source_t``, s: how far behind the producer's clock the rider reads, delivery included)."""
    later = [f for f in frames if f["at"] >= frames[0]["at"] + 1.5]
    exact = set(stamps)
    held = sum(f["source_t"] in exact for f in later) / len(later)
    lateness = [stamps[bisect.bisect_right(sent, f["at"]) - 1] - f["source_t"] for f in later]
    return held, np.array(lateness)


def test_a_clock_5_percent_slow_or_fast_is_tracked_without_resets(server: LiveServer) -> None:
    """A producer whose clock runs 5 % slow (a game at a fixed timestep on a busy host) or 5 %
    fast against ours, over the real websocket at 120 frames a second: no segment (no reset),
    the producer drives every frame (no lost control), the rider reads between frames about
    as often as with a steady clock (the old mapping, 5 % slow: it held the newest frame on
    every frame, up to 0.2 s ahead of the frames' own timing; held share 1.0 against 0.0
    steady), and its lateness is bounded: never ahead of the producer, its median within
    20 ms of a steady clock's in the same run, not growing (the last second's median within
    20 ms of the steady clock's), its largest within 0.1 s of the steady clock's largest (delivery
    on a loaded host)."""
    steady_sent: list[float] = []
    steady, none, steady_stamps = run(server, 4.0, lambda e: e, game=True, sent=steady_sent)
    assert none == []
    held_steady, steady_late = held_and_late(steady, steady_stamps, steady_sent)
    for rate in (0.95, 1.05):
        sent: list[float] = []
        frames, segments, stamps = run(server, 6.0, lambda e, r=rate: r * e, game=True, sent=sent)  # type: ignore[misc]
        assert segments == [], (rate, segments)
        assert all(f["driver"] == "input" for f in frames), (rate, drivers(frames))
        held, late = held_and_late(frames, stamps, sent)
        figures = (rate, held, held_steady, np.median(late), late.max(), np.median(steady_late), steady_late.max())
        assert held <= held_steady + 0.15, figures
        assert late.min() >= 0.0, figures
        assert np.median(late) <= np.median(steady_late) + 0.02 and late.max() <= steady_late.max() + 0.1, figures
        # not growing: the last second is no later than a steady clock's lateness (+ 20 ms). A
        # drift left untracked grows 50 ms a second here; the tracked one settles toward the
        # steady clock's lateness from below (first second 8.8 ms, last 20.4, steady 27.8: a
        # fresh-clone run), which a first-vs-last comparison took for growth
        second = len(late) * 120 // 540  # about one second of frames
        assert np.median(late[-second:]) <= np.median(steady_late) + 0.02, figures
