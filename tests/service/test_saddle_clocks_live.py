"""A saddle producer's clock against the real server (uvicorn, a real websocket producer on
``/ws/saddle``, a ``/ws/rider`` follower): the same cases as the horse path
(``test_clocks_live.py``, docs/protocol.md "Clocks that jump" and "Clocks that drift"): a
clock 5 % slow or fast is tracked without resets, every sample stepped and driving, the
lateness bounded; a frozen timestamp and small steps back keep the producer in control."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from riderlive.realtime.resample import MAX_SKEW
from riderlive.realtime.tick_control import RATE_SHOWN
from riderlive.saddle import Model
from tests.service.live_server import LiveServer
from tests.service.test_clocks_live import (
    DELAY,
    driven_while_sent,
    drivers,
    largest_step,
    lateness,
    run,
    steps_back,
)
from tests.service.test_saddle_live import _trot_saddle
from tests.waiting import wait_until

SETTLE = 2.0
"""Seconds of a steady clock first: the estimator locks the trot (2 strides of 1.4 Hz) before the case."""
STALE_S = Model().hold + Model().ease
"""A saddle stream with no sample for this long is stale, and the rider eases to neutral
(``realtime/saddle_input.py``): what the service must do when its producer falls silent."""


def saddle_frame(t: float, at: float) -> dict[str, Any]:
    """A /ws/saddle sample stamped ``t`` showing the trotting saddle at time ``at``."""
    return {**_trot_saddle(at), "t": t}


def driven(frame: dict[str, Any]) -> bool:
    """Driven by the input: the test's saddle producer, the only one connected."""
    return frame["driver"] == "input"


def every_sample_taken(server: LiveServer) -> tuple[Callable[[list[float]], None], list[float]]:
    """A ``before_close`` that waits (producer still connected) until the tick has stepped
    the estimator with every sample sent since it was made (``riderlive_saddle_samples_total``),
    and the tick's refused-as-older count then (``[refused]``)."""
    samples = server.metric("riderlive_saddle_samples_total")
    refused = server.metric("riderlive_tick_input_out_of_order_total")
    out: list[float] = []

    def wait(stamps: list[float]) -> None:
        wait_until(
            lambda: server.metric("riderlive_saddle_samples_total") - samples >= len(stamps),
            10.0,
            "the tick never stepped every sample sent",
        )
        out.append(server.metric("riderlive_saddle_samples_total") - samples - len(stamps))
        out.append(server.metric("riderlive_tick_input_out_of_order_total") - refused)

    return wait, out


def ahead_and_late(
    frames: list[dict], stamps: list[float], sent: list[float], skip: float = 1.5, at: str = "ticked"
) -> tuple[float, np.ndarray]:
    """Of the frames from ``skip`` s on: the share read past the newest sample sent before the
    frame was ticked (extrapolated), and each one's lateness (that sample's stamp minus the
    frame's ``source_t``, s; the delivery to the tick included, the delivery to this follower
    not: ``test_clocks_live.held_and_late``). ``at="at"``: the newest sample sent before the
    frame reached this follower instead, the least lateness (a tick that ran late read the
    samples that came until it ran: past its deadline's newest, not past the newest)."""
    later = lateness([f for f in frames if f["ticked"] >= frames[0]["ticked"] + skip], stamps, sent, at)
    return float(np.mean(later < 0.0)), later


class RateWatch:
    """The saddle clock rate in use as ``/metrics`` shows it (the tick's, from shared memory),
    read every ``every`` s on a thread from the ``with`` until :meth:`finish`: ``seen`` holds
    (perf_counter s when the answer came, rate). Finish while the producer is connected: the
    stream's mapping starts afresh when it leaves (rate 1; a reading after that, on a busy
    host, once made the rate look never followed)."""

    def __init__(self, server: LiveServer, every: float = 0.1) -> None:
        self.server, self.every = server, every
        self.seen: list[tuple[float, float]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, daemon=True)

    def _read(self) -> float:
        rate = self.server.metric("riderlive_input_clock_rate", 'kind="saddle"')
        self.seen.append((time.perf_counter(), rate))
        return rate

    def _watch(self) -> None:
        while not self._stop.wait(self.every):
            self._read()

    def __enter__(self) -> RateWatch:
        self._thread.start()
        return self

    def _halt(self) -> None:
        self._stop.set()
        self._thread.join()

    def finish(self) -> float:
        """No more readings but one now (the thread's last may not have been): its rate."""
        self._halt()
        return self._read()

    def __exit__(self, *_: object) -> None:
        self._halt()

    def shown(self, since: float) -> list[tuple[float, float]]:
        """The answers from ``since`` on: (s after it, rate), rounded for a message."""
        return [(round(at - since, 2), round(rate, 4)) for at, rate in self.seen if at >= since]

    def followed(self, change: float, since: float) -> float | None:
        """Seconds from ``since`` to the first answer showing a rate within 10 % of ``change``
        (the rate's change from 1) with every later answer too (None: not by the last one)."""
        out: float | None = None
        for at, rate in self.seen:
            close = at >= since and abs((rate - 1.0) / change - 1.0) <= 0.1
            out = (at - since if out is None else out) if close else None
        return out


def settled_from(
    frames: list[dict[str, Any]], lateness: np.ndarray, followed: float, change: float, every: float
) -> float:
    """Seconds from the first frame by which the read can no longer be past the newest sample:
    ``followed`` (the rate shown within 10 % of ``change``, on the watch's answers ``every``
    s apart) plus the catch-up of the read past the newest sample then (the largest over the
    two answers before), at the mapping's slew (``resample.MAX_SKEW`` of the producer's
    progress, less the 10 % of the change still off). ``lateness``: each frame's, as
    :func:`ahead_and_late` gives it with ``skip=0``."""
    t0 = frames[0]["ticked"]
    times = np.array([f["ticked"] - t0 for f in frames])
    near = (times >= followed - 2 * every) & (times <= followed)
    past = max(0.0, float(-lateness[near].min())) if near.any() else 0.0
    # ``past`` is producer seconds (1 + change of ours each); the mapping moves by MAX_SKEW of
    # each producer second (1 / (1 + change) of them in one of ours), less the rate still off
    slew = (MAX_SKEW - 0.1 * abs(change)) / (1.0 + change)  # our s per our s
    return followed + past * (1.0 + change) / slew


def longest_silence(sent: list[float]) -> float:
    """The longest this test's sender sent nothing (s), for a message."""
    return max((b - a for a, b in zip(sent, sent[1:])), default=0.0)


def held_by_sender(sent: list[float], done: list[float]) -> float:
    """The longest this test's sender took to send a sample beyond the usual (the largest time
    from its stamp to its send's return less the median, s): the sample reached the service
    that much later against its stamp, as if the service had been late (the stamp is taken
    just before the send: a sender descheduled between them, on a busy host, sends it late)."""
    took = np.array(done) - np.array(sent)
    return float(took.max() - np.median(took))


def held_by_host(frames: list[dict]) -> float:
    """The longest the host held a frame between its tick and this follower beyond the usual
    (the largest ``at - ticked`` less the median, s): a witness of a stall of the service's web
    process, which receives the producer's samples in the same event loop that forwards the
    tick's frames, so a sample it got late was held as long. (A stall of this follower shows
    here too: the witness errs toward a larger allowance, never a smaller one.)"""
    held = np.array([f["at"] - f["ticked"] for f in frames])
    return float(held.max() - np.median(held))


def test_a_saddle_clock_5_percent_slow_or_fast_is_tracked_without_resets(server: LiveServer) -> None:
    """As the horse's (``test_clocks_live``): 6 s of a saddle clock at 0.95 and 1.05 x ours,
    120 samples a second, against a steady clock in the same run: no segment, every frame
    driven by the saddle, every sample stepped (none refused), the rate the same in
    /api/state (within 0.1 %) and /metrics, within 10 % of the change from 1 to 1 / rate; the read
    past the newest sample, once settled (:func:`settled_from`: the rate followed and the
    read caught up at the mapping's slew), on at most 1 % more frames than the steady clock's, the lateness
    never growing: median and last second's median within 20 ms of the steady clock's,
    largest within 0.1 s of its largest. Old code (rate taken as 1), 5 % slow: largest
    lateness 248 ms against the steady 52 ms (the drift went into the read delay).

    The read delay follows the latest arrival of the last 10 s (``saddle_input.LATE_MEMORY_S``,
    documented): a sample the host delivered late raises the lateness of every frame after
    it in the run. So the medians' bounds add what the follower saw the host hold a frame
    (:func:`held_by_host`, over the whole stream, its settle too: the memory spans both)
    and what this test's sender took to send one (:func:`held_by_sender`), beyond what
    they were in the steady run: a -n 2 run's other worker once raised the last second's
    median to 51 ms against the steady 27 ms so; a fresh clone's (cold numba cache) the
    whole run's to 155 ms, when the measured part alone showed 67 ms; another's the 5 %
    fast run's to 101 ms against the steady 28 ms, the host's hold 36 ms beyond the
    steady run's (the sender's not yet measured then)."""
    steady_sent: list[float] = []
    steady_whole: list[dict] = []
    steady_done: list[float] = []
    wait, _ = every_sample_taken(server)
    steady, none, steady_stamps = run(
        server,
        4.0,
        lambda e: e,
        True,
        steady_sent,
        path="/ws/saddle",
        make=saddle_frame,
        settle=SETTLE,
        before_close=wait,
        whole=steady_whole,
        done=steady_done,
    )
    assert none == [] and all(driven(f) for f in steady), drivers(steady)
    steady_ahead, steady_late = ahead_and_late(steady, steady_stamps, steady_sent)
    steady_past, _ = ahead_and_late(steady, steady_stamps, steady_sent, at="at")
    for rate in (0.95, 1.05):
        sent: list[float] = []
        whole: list[dict] = []
        done: list[float] = []
        wait, taken = every_sample_taken(server)
        rates: list[float] = []
        watch = RateWatch(server)

        def shown(
            stamps: list[float],
            wait: Callable[[list[float]], None] = wait,
            rates: list[float] = rates,
            watch: RateWatch = watch,
        ) -> None:
            wait(stamps)  # every sample stepped: the rate is final
            rates.append(watch.finish())
            wait_until(
                lambda: abs(server.get("/api/state").json()["tick"]["saddle_clock_rate"] - rates[0]) <= RATE_SHOWN,
                5.0,
                "/api/state never showed the rate /metrics shows (within tick.RATE_SHOWN)",
            )

        with watch:
            frames, segments, stamps = run(
                server,
                6.0,
                lambda e, r=rate: r * e,  # type: ignore[misc]
                True,
                sent,
                path="/ws/saddle",
                make=saddle_frame,
                settle=SETTLE,
                before_close=shown,
                whole=whole,
                done=done,
            )
        assert segments == [], (rate, segments)
        assert all(driven(f) for f in frames), (rate, drivers(frames))
        assert taken == [0.0, 0.0], ("every sample stepped once, none refused", rate, taken)
        # the baseline restarts at the change of rate (resample.RATE_CHANGE): within 10 % of
        # 1 / rate 6 s on (measured 0.999-1.001, quiet; old code, one 10 s baseline holding
        # the steady clock's 2 s: 0.5-0.7)
        assert 0.9 <= (rates[0] - 1.0) / (1.0 / rate - 1.0) <= 1.1, (rate, rates)
        ahead, late = ahead_and_late(frames, stamps, sent)
        held = held_by_host(whole) + held_by_sender(sent, done)
        host = max(0.0, held - held_by_host(steady_whole) - held_by_sender(steady_sent, steady_done))
        steady_figures = (np.median(steady_late), steady_late.max())
        figures = (rate, ahead, steady_ahead, np.median(late), late.max(), *steady_figures, host)
        # When the rate in use came within 10 % of the change, watched live (measured, quiet
        # and beside two busy loops: 5 % slow 2.4-3.5 s, 5 % fast 1.0 s; docs/protocol.md
        # "Clocks that drift" for why a slowing clock is followed later).
        change = 1.0 / rate - 1.0
        followed = watch.followed(change, frames[0]["ticked"])
        assert followed is not None, (rate, rates, watch.shown(frames[0]["ticked"]))
        # Read past the newest sample: only while the mapping settles, so none from when the
        # rate was followed and the read caught up (5 % slow, measured: the last such frame
        # 2.3-2.9 s on, before the rate was shown followed), judged on the samples sent
        # before the frame reached this follower. A fixed "from 3 s" failed once in CI
        # (-n 2): 2.9 % of the frames after it, the change judged late; and judged at the
        # frames' deadlines, a -n 2 run once had 7 of 657 frames after the settle past the
        # newest sample sent by then (the steady run 0), as the horse's did.
        _, every_late = ahead_and_late(frames, stamps, sent, skip=0.0)
        since = settled_from(frames, every_late, followed, change, watch.every)
        settled, _ = ahead_and_late(frames, stamps, sent, skip=since, at="at")
        assert settled <= steady_past + 0.01, (settled, since, followed, steady_past, *figures)
        assert np.median(late) <= np.median(steady_late) + 0.02 + host, figures
        assert late.max() <= steady_late.max() + 0.1, figures
        second = len(late) * 120 // 540  # about one second of frames
        assert np.median(late[-second:]) <= np.median(steady_late) + 0.02 + host, figures


def test_a_frozen_saddle_timestamp_and_small_steps_back_keep_the_saddle_driving(server: LiveServer) -> None:
    """A saddle sensor whose timestamp freezes for 1.5 s while its samples keep coming, then
    moves on; and one whose stamps step back 0.2 s every second: the horse path's behaviour
    (docs/protocol.md "Clocks that jump"): ``clock_paused`` within 0.5 s of the freeze then
    ``clock_resumed``, each step back one ``clock_backward`` re-anchored; the saddle drives
    every frame (never neutral, never the procedural horse) and the rider's per-tick step
    stays within 1.5 x a steady clock's. Frames ticked after this test's own sender fell
    silent longer than the stream's hold are not the clock's (``test_clocks_live.excused``);
    nor, for the step, those after a silence longer than ``input.delay`` (``DELAY``, the least
    the saddle's read delay is): the read passed the newest sample and held the pose, and the
    step when samples came again is that hold's, documented, as on the horse's path (the
    steps were judged over silences of the hold before: once, quiet, 4.4 x a steady clock's)."""
    # as long as the longest run compared with it: the largest step of a shorter window is
    # biased low (a 2 s baseline put the 3.5 s stepping run at 1.55 x once, quiet host)
    sent: list[float] = []
    baseline, none, _ = run(server, 3.5, lambda e: e, False, sent, path="/ws/saddle", make=saddle_frame, settle=SETTLE)
    ok, runs = driven_while_sent(baseline, sent, STALE_S)
    assert none == [] and ok, runs
    bound = largest_step(baseline, sent, DELAY)

    paused_before = server.metric("riderlive_clock_jumps_total", 'direction="paused"')
    sent = []
    paused, segments, _ = run(
        server,
        3.0,
        lambda e: min(e, 0.5) + max(0.0, e - 2.0),
        False,
        sent,
        path="/ws/saddle",
        make=saddle_frame,
        settle=SETTLE,
    )
    assert [s["reason"] for s in segments] == ["clock_paused", "clock_resumed"], segments
    assert -0.5 <= segments[0]["jump"] < 0.0, segments  # a segment within 0.5 s of the freeze
    ok, runs = driven_while_sent(paused, sent, STALE_S)
    assert ok, ("the saddle kept control throughout", runs)
    step = largest_step(paused, sent, DELAY)
    assert step <= 1.5 * bound, (step, bound, longest_silence(sent))
    assert server.metric("riderlive_clock_jumps_total", 'direction="paused"') == paused_before + 1

    sent = []
    stepping, segments, stamps = run(
        server, 3.5, lambda e: e - 0.2 * math.floor(e), False, sent, path="/ws/saddle", make=saddle_frame, settle=SETTLE
    )
    back = steps_back(stamps)
    assert len(back) >= 2, ("the sender was late across more than one step", back)
    assert [s["reason"] for s in segments] == ["clock_backward"] * len(back), (segments, back)
    assert [(s["previous_t"], s["t"]) for s in segments] == back, (segments, back)
    ok, runs = driven_while_sent(stepping, sent, STALE_S)
    assert ok, runs
    step = largest_step(stepping, sent, DELAY)
    assert step <= 1.5 * bound, (step, bound, longest_silence(sent))
