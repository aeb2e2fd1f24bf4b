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
    done: list[float] | None = None,
) -> None:
    """Send a smooth horse (or ``make(stamp, time shown)``'s frames) at HZ, stamped with
    ``clock(elapsed)``: a function of that clock (``game``: a game's pose follows its clock,
    and stands still with it) or of real time (a producer whose timestamps alone step);
    collect the segment messages that come back and the stamps sent (``stamps``, in order;
    ``sent``: when each send began, ``done``: when it returned, perf_counter s)."""
    start = time.perf_counter()
    n = 0
    while (elapsed := time.perf_counter() - start) < seconds:
        t = clock(elapsed)
        if sent is not None:
            sent.append(time.perf_counter())  # before the send: no frame can arrive before it
        ws.send(json.dumps(make(t, t if game else elapsed)))
        if done is not None:
            done.append(time.perf_counter())
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


HOLD, DELAY = 0.5, 0.03
"""``input.hold`` and ``input.delay`` of the test server (tests/service/conftest.py): a producer
silent longer than HOLD is stale; silent longer than DELAY, the tick holds its newest frame."""
IN_FLIGHT_S = 0.1
"""Allowed for a frame sent to reach the tick (the web process's receive, the ring, a tick)."""


def excused(frames: list[dict[str, Any]], sent: list[float], silent_for: float) -> list[bool]:
    """Per ``/ws/rider`` frame: ticked after a silence of more than ``silent_for`` s that is not
    the service's clock handling, whose effect (a held frame and the step after it past
    ``input.delay``, the ease to neutral past ``input.hold``) is then documented behaviour,
    not the case's:

    - this test's own sender had sent nothing for ``silent_for`` (or had just sent again:
      ``IN_FLIGHT_S`` for its frame to reach the tick). The sender and the follower share
      this process: a stall of it (descheduled, or held by a garbage collection) silences the
      producer. In a full run (fresh clone, quiet) the saddle's sender fell silent ~1.3 s in
      a settle (the follower, in the same process, was 0.98 s behind); the rider went neutral
      as specified, and drove again at the next frame;
    - the follower got nothing for ``silent_for`` before it, or ``IN_FLIGHT_S`` before it:
      the service's web process was descheduled (it forwards the producer's frames to the
      tick and the tick's to the follower: both came in a burst). CI once saw 13 neutral
      frames 0.5 s after a resume, the cause not kept (test_clocks_live, 2026-11-28).

    ``sent``: send times (perf_counter s) in order; a frame's ``ticked`` is its tick time on
    this process's clock (:class:`~tests.service.producers.Follower`)."""
    ats = [f["at"] for f in frames]
    sender = [(a, b) for a, b in zip(sent, sent[1:]) if b - a > silent_for]
    resumed = [b for a, b in zip(ats, ats[1:]) if b - a > silent_for]
    out: list[bool] = []
    for f in frames:
        ticked = f["ticked"]
        silent = (
            not sent
            or ticked <= sent[0] + IN_FLIGHT_S
            or any(a + silent_for < ticked <= b + IN_FLIGHT_S for a, b in sender)
        )
        k = bisect.bisect_right(resumed, f["at"])
        out.append(bool(silent or (k > 0 and f["at"] - resumed[k - 1] <= IN_FLIGHT_S)))
    return out


def driven_while_sent(frames: list[dict[str, Any]], sent: list[float], stale: float = HOLD) -> tuple[bool, Any]:
    """Whether the producer drove every frame but those :func:`excused` for a silence over
    ``stale`` (the stream's hold), and for the message the driver runs and the frames excused."""
    out = excused(frames, sent, stale)
    ok = all(f["driver"] == "input" or gone for f, gone in zip(frames, out, strict=True))
    return ok, (drivers(frames), "frames ticked after a silence not the service's:", sum(out))


def largest_step(frames: list[dict[str, Any]], sent: list[float], held: float = DELAY) -> float:
    """The largest change of the rider's lower back per tick between consecutive /ws/rider
    frames (deg; a frame the follower missed makes a two-tick step, counted as two), over
    the steps between two frames not :func:`excused` for a silence over ``held`` (the read
    passed the newest frame and held it: the step when frames come again is the hold's; a
    68 ms sender stall, loaded, made one of 3 x a steady clock's)."""
    back = np.array([f["values"][BACK] for f in frames])
    seq = np.array([f["seq"] for f in frames])
    kept = ~np.array(excused(frames, sent, held))
    steps = (np.abs(np.diff(back)) / np.diff(seq))[kept[1:] & kept[:-1]]
    return float(steps.max())


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
    whole: list[dict] | None = None,
    done: list[float] | None = None,
) -> tuple[list[dict], list[dict], list[float]]:
    """``settle`` s on a steady clock, then ``seconds`` on ``clock``, without a break in the
    stream to ``path``; the follower's frames of the second part, the segment messages and
    the stamps sent (``sent``: when each was sent; ``done``: when each send returned, the
    settle's too). ``before_close(stamps)`` runs after the last send, while the producer is
    still connected. ``whole`` gets every frame of the stream, the settle's too."""
    follower = Follower(server.ws)
    segments: list[dict] = []
    stamps: list[float] = []
    try:
        with connect(server.ws + path) as ws:
            ws.recv(timeout=5)
            connected = time.perf_counter()
            begin = connected + settle
            drive(
                ws,
                settle + seconds,
                lambda e: 1000.0 + e if e < settle else 1000.0 + settle + clock(e - settle),
                segments,
                game,
                stamps,
                sent,
                make,
                done,
            )
            end = time.perf_counter()
            if before_close is not None:
                before_close(stamps)
        frames = [f for f in follower.frames if begin + 0.05 <= f["at"] <= end]
        if whole is not None:
            whole.extend(f for f in follower.frames if connected <= f["at"] <= end)
        assert frames and any(f["driver"] == "input" for f in follower.frames if f["at"] < begin), "it drove at once"
        return frames, segments, stamps
    finally:
        follower.close()


def test_a_paused_clock_and_a_stepping_clock_keep_driving_without_jumps(server: LiveServer) -> None:
    sent: list[float] = []
    baseline, none, _ = run(server, 2.0, lambda e: e, game=True, sent=sent)
    ok, runs = driven_while_sent(baseline, sent)
    assert none == [] and ok, runs
    bound = largest_step(baseline, sent)

    paused_before = server.metric("riderlive_clock_jumps_total", 'direction="paused"')
    # the game pauses after 0.5 s for 1.5 s (its clock stands still, frames keep coming), then resumes
    sent = []
    paused, segments, _ = run(server, 3.0, lambda e: min(e, 0.5) + max(0.0, e - 2.0), game=True, sent=sent)
    reasons = [s["reason"] for s in segments]
    assert reasons == ["clock_paused", "clock_resumed"], segments
    ok, runs = driven_while_sent(paused, sent)
    assert ok, ("the producer kept control throughout", runs)
    assert -0.5 <= segments[0]["jump"] < 0.0  # it stood still for less than 0.5 s before the segment
    assert largest_step(paused, sent) <= 1.5 * bound, (largest_step(paused, sent), bound)
    assert server.metric("riderlive_clock_jumps_total", 'direction="paused"') == paused_before + 1

    # 0.2 s back every second (the issue: every 2 s; twice as many steps here)
    sent = []
    stepping, segments, stamps = run(server, 3.5, lambda e: e - 0.2 * math.floor(e), game=False, sent=sent)
    back = steps_back(stamps)
    # 3 steps sent, unless the sender was late across one (seen once in a full suite on a loaded host)
    assert len(back) >= 2, ("the sender was late across more than one step", back)
    # each step sent is one segment, told with the two stamps around it
    assert [s["reason"] for s in segments] == ["clock_backward"] * len(back), (segments, back)
    assert [(s["previous_t"], s["t"]) for s in segments] == back, (segments, back)
    # the step is 0.2 s less the time between the two frames (8 ms at 120 Hz, more when the
    # sender is late: by 0.15 s, -0.05 s; the two stamps are checked exactly above)
    assert all(s["jump"] == s["t"] - s["previous_t"] and -0.2 < s["jump"] < 0.0 for s in segments), segments
    ok, runs = driven_while_sent(stepping, sent)
    assert ok, runs
    assert largest_step(stepping, sent) <= 1.5 * bound, (largest_step(stepping, sent), bound)


def lateness(frames: list[dict], stamps: list[float], sent: list[float], at: str = "ticked") -> np.ndarray:
    """Each frame's lateness: the newest stamp whose send began before the frame's ``at`` time
    (``ticked``: its tick's deadline; ``at``: its arrival here) minus its ``source_t`` (s)."""
    return np.array([stamps[bisect.bisect_right(sent, f[at]) - 1] - f["source_t"] for f in frames])


def held_and_late(
    frames: list[dict], stamps: list[float], sent: list[float], at: str = "ticked"
) -> tuple[float, np.ndarray]:
    """Of the frames from 1.5 s on (the clock's rate estimated): the share that held the newest
    frame (a frame's ``source_t`` is a stamp itself: not interpolated), and each one's
    lateness (the newest stamp whose send began before the frame was ticked minus its
    ``source_t``, s: how far behind the producer's clock the rider reads, the delivery to the
    tick included, the delivery to this follower not: a -n 2 run's follower, descheduled,
    once made 0.19 s of it).

    ``ticked`` is the tick's deadline; a tick that ran late read the frames that came until it
    ran. So the lateness at the deadline (``at="ticked"``) is the most it can be, and at the
    frame's arrival here (``at="at"``) the least: a read ahead of the producer shows below 0
    there. (At the deadline, a 35 ms pause of this test's sender just before a tick that ran
    late made -10 ms once, a -n 2 run.)"""
    later = [f for f in frames if f["ticked"] >= frames[0]["ticked"] + 1.5]
    exact = set(stamps)
    held = sum(f["source_t"] in exact for f in later) / len(later)
    return held, lateness(later, stamps, sent, at)


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
        assert held_and_late(frames, stamps, sent, at="at")[1].min() >= 0.0, figures  # never ahead
        assert np.median(late) <= np.median(steady_late) + 0.02 and late.max() <= steady_late.max() + 0.1, figures
        # not growing: the last second is no later than a steady clock's lateness (+ 20 ms). A
        # drift left untracked grows 50 ms a second here; the tracked one settles toward the
        # steady clock's lateness from below (first second 8.8 ms, last 20.4, steady 27.8: a
        # fresh-clone run), which a first-vs-last comparison took for growth
        second = len(late) * 120 // 540  # about one second of frames
        assert np.median(late[-second:]) <= np.median(steady_late) + 0.02, figures
