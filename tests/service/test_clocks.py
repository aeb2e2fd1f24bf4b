"""A producer's clock against the service's (pure, on scripted clocks): jumps, steps back,
a clock that stands still, its resume, and the cap on segments."""

from __future__ import annotations

import random

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from riderlive.channels import HORSE_NAMES
from riderlive.horse import ProceduralHorse
from riderlive.realtime.core import Driver, TickCore, Timing
from riderlive.rules import RiderModel
from riderlive.service.clocks import (
    MAX_SEGMENTS_PER_S,
    MIN_PAUSE_S,
    STEP_S,
    ClockEvent,
    ClockStep,
    ProducerClock,
    clock_step,
)

JUMP, PAUSE = 0.5, 0.1
DT = 1 / 120


def feed(frames: list[tuple[float, float]], pause: float = PAUSE) -> list[ClockStep]:
    """(producer t, receive time) per frame -> each frame's step."""
    clock, out = ProducerClock(), []
    for t, rx in frames:
        step = clock_step(clock, t, rx, JUMP, pause)
        clock = step.clock
        out.append(step)
    return out


def events(steps: list[ClockStep]) -> list[tuple[int, ClockEvent]]:
    return [(i, s.event) for i, s in enumerate(steps) if s.event is not None]


def test_a_steady_clock_passes_through() -> None:
    steps = feed([(50.0 + i * DT, 7.0 + i * DT + (0.003 if i % 3 else 0.0)) for i in range(500)])  # jitter 3 ms
    assert events(steps) == []
    assert [s.t for s in steps] == [50.0 + i * DT for i in range(500)]


def test_a_jump_either_way_starts_a_segment() -> None:
    frames = [(100.0 + i * DT, i * DT) for i in range(10)]
    frames += [(0.0 + i * DT, (10 + i) * DT) for i in range(10)]  # a scene reload
    frames += [(5000.0 + i * DT, (20 + i) * DT) for i in range(10)]
    steps = feed(frames)
    assert events(steps) == [(10, ClockEvent.BACKWARD), (20, ClockEvent.FORWARD)]
    assert steps[10].new_stream and steps[20].new_stream and [s.t for s in steps] == [t for t, _ in frames]
    assert steps[10].previous_t == 100.0 + 9 * DT and steps[10].jump < -100.0 and steps[20].jump > 4000.0


def test_a_clock_that_stands_still_is_paused_after_4_of_its_steps_and_the_service_clock_stands_in() -> None:
    frames = [(10.0 + i * DT, i * DT) for i in range(60)]
    paused_at = frames[-1][0]
    frames += [(paused_at, (60 + i) * DT) for i in range(1, 200)]  # the game paused; frames keep coming
    frames += [(paused_at + i * DT, (260 + i) * DT) for i in range(1, 30)]  # and resumes where it was
    steps = feed(frames)
    (p, paused), (r, resumed) = events(steps)
    assert paused is ClockEvent.PAUSED and resumed is ClockEvent.RESUMED and r == 259
    # paused once the clock stood still for 4 of its 1/120 s steps (33 ms), not a frame later
    still = frames[p][1] - frames[59][1]
    assert 4 * DT - 1e-9 <= still < 5 * DT and steps[p].jump == -still
    # from the pause on, the time given to the tick goes on from the last frame that moved
    # with the service's clock: continuous, the same stream (no blend)
    given = [s.t for s in steps[p:]]
    received = [rx for _, rx in frames[p:]]
    assert given[0] == paused_at + still
    assert all(abs((g - given[0]) - (x - received[0])) < 1e-9 for g, x in zip(given[: r - p], received))
    # resumed: its own clock again, plus the offset that keeps the time given continuous
    offset = steps[r].t - frames[r][0]
    assert all(abs(s.t - (t + offset)) < 1e-9 for s, (t, _) in zip(steps[r:], frames[r:]))
    assert not any(s.new_stream for s in steps)
    times = [s.t for s in steps]
    assert all(b >= a for a, b in zip(times, times[1:])), "the time given never goes back"
    assert all(b > a for a, b in zip(times[p - 1 :], times[p:])), "nor stands still once paused"


@pytest.mark.parametrize(
    ("hz", "still"),
    [(1000.0, MIN_PAUSE_S), (200.0, 0.02), (60.0, 4 / 60), (30.0, PAUSE), (10.0, PAUSE)],
)
def test_the_stand_still_taken_for_a_pause_is_4_steps_of_the_producer_within_10_ms_and_pause_s(
    hz: float, still: float
) -> None:
    """At 200 Hz a frozen timestamp is noticed after 20 ms, not 0.1 s: the 0.1 s of frames
    dropped before then let the tick read past the newest sample into a held pose, then step
    (the live 1.6x step, docs/performance.md). Never before 10 ms; never after ``pause_s``."""
    dt = 1 / hz
    frames = [(5.0 + i * dt, 2.0 + i * dt) for i in range(40)]
    frames += [(frames[-1][0], 2.0 + (40 + i) * dt) for i in range(round(0.3 * hz))]
    steps = feed(frames)
    (p, paused), *_ = events(steps)
    assert paused is ClockEvent.PAUSED
    stood = frames[p][1] - frames[39][1]  # paused at the first frame after ``still``, not later
    assert still - 1e-9 <= stood < still + dt + 1e-9 and -steps[p].jump == pytest.approx(stood)


def test_a_clock_coarser_than_its_frames_and_duplicated_frames_are_no_pause() -> None:
    """240 frames a second on a clock that moves at 120 Hz (every t twice), and a 1000 Hz
    stream whose every tenth frame comes twice: the stand-still never reaches 4 steps."""
    coarse = [(1.0 + (i // 2) / 120, i / 240) for i in range(600)]
    doubled = [(1.0 + i / 1000, i / 1000 + (0.0005 if i % 10 == 0 else 0.0)) for i in range(2000)]
    doubled = [f for i, f in enumerate(doubled) for _ in range(2 if i % 10 == 0 else 1)]
    assert events(feed(coarse)) == [] and events(feed(doubled)) == []


def test_a_step_back_in_a_burst_after_a_delivery_stall_advances_one_step_of_the_producer() -> None:
    """A 200 Hz producer whose delivery stalled 60 ms: its frames then arrive 0.1 ms apart,
    and the one stepped back 0.2 s is given one of its 5 ms steps after the newest, as the
    producer made it, not the 0.1 ms of the burst (which crowded the pose of 5 ms into 0.1
    ms: a one-tick step of the rider)."""
    dt = 1 / 200
    frames = [(1.0 + i * dt, i * dt) for i in range(40)]
    burst = 40 * dt + 0.06
    frames += [(1.0 + (40 + i) * dt, burst + i * 1e-4) for i in range(12)]
    frames += [(1.0 + 52 * dt - 0.2, burst + 12e-4)]
    steps = feed(frames)
    assert events(steps) == [(52, ClockEvent.BACKWARD)]
    assert steps[52].t - steps[51].t == pytest.approx(dt)


def test_small_backward_steps_are_re_anchored() -> None:
    """0.2 s back every 2 s, as in the issue: every step is a segment, no frame is lost."""
    frames = [(i * DT - 0.2 * (i // 240), i * DT) for i in range(1200)]
    steps = feed(frames)
    assert events(steps) == [(i, ClockEvent.BACKWARD) for i in range(240, 1200, 240)]
    assert all(abs(steps[i].jump + 0.2 - DT) < 1e-9 for i in range(240, 1200, 240))
    assert not any(s.new_stream for s in steps), "re-anchored in the same stream"
    for a, b in zip(steps, steps[1:]):  # the time given advances with the service's clock, step or not
        assert abs((b.t - a.t) - DT) < 1e-9


def test_jitter_below_a_millisecond_is_no_segment() -> None:
    frames = [(1.0, 0.0), (1.01, 0.01), (1.01 - STEP_S / 2, 0.02), (1.03, 0.03)]
    assert events(feed(frames)) == []


def test_a_clock_that_goes_back_on_every_frame_starts_at_most_the_cap_of_segments_a_second() -> None:
    frames = [(-0.01 * i, i * DT) for i in range(600)]  # 5 s, every frame 10 ms older
    steps = feed(frames)
    small = [frames[i][1] for i, _ in events(steps) if abs(steps[i].jump) <= JUMP]
    assert small[:4] == [frames[i][1] for i in range(1, 5)]  # the first four at once
    for start in small:  # then at most the cap in any second
        assert sum(1 for x in small if start <= x < start + 1.0) <= MAX_SEGMENTS_PER_S
    # once dropped frames add up to a jump, that is a jump (not capped): every 0.5 s here
    big = [i for i, _ in events(steps) if abs(steps[i].jump) > JUMP]
    assert 8 <= len(big) <= 11


frame_gaps = st.floats(min_value=0.0, max_value=0.05)
clock_moves = st.one_of(
    st.just(0.0), st.floats(min_value=-0.3, max_value=0.3), st.floats(min_value=-1e3, max_value=1e3)
)


@given(st.lists(st.tuples(frame_gaps, clock_moves), min_size=1, max_size=300))
def test_invariants(moves: list[tuple[float, float]]) -> None:
    """Whatever the clock does: step and pause segments stay within the cap in every
    second; the time given is finite; while the service's clock stands in, it advances
    exactly with the receive time."""
    t = rx = 0.0
    frames = []
    for gap, move in moves:
        rx += gap
        t += move
        frames.append((t, rx))
    steps = feed(frames)
    # steps back and pauses are capped (a jump, drift beyond JUMP, is not: its jump is > JUMP)
    capped = [
        frames[i][1]
        for i, e in events(steps)
        if e is ClockEvent.PAUSED or (e is ClockEvent.BACKWARD and abs(steps[i].jump) <= JUMP)
    ]
    for start in capped:
        assert sum(1 for x in capped if start <= x < start + 1.0) <= MAX_SEGMENTS_PER_S
    previous = None
    for (_, rx), s in zip(frames, steps):
        assert abs(s.t) < 1e9
        if s.clock.standin is not None and s.event is None:
            t0, rx0 = s.clock.standin
            assert s.t == t0 + (rx - rx0)
        if s.event is not None and not s.new_stream and previous is not None:
            assert s.t >= previous.newest_eff - 1e-9, "a re-anchor never goes back"
        previous = s.clock


@pytest.mark.parametrize("stall", [(1.0, 0.2), (2.4, 0.2), (2.45, 0.1), (2.5, 0.2)])
def test_a_delivery_stall_across_a_pause_or_its_resume_leaves_the_clock_rate_alone(
    stall: tuple[float, float],
) -> None:
    """A game at 120 Hz on a steady clock pauses at 1.0 s and resumes at 2.5 s (its time) while
    its frames stand still in delivery (``stall``: from, for how long, s; 2 ms of jitter) and
    come in a burst: the time given at the pause or the resume is then taken from a late
    arrival, a step in the offsets. Fed through ``clock_step`` to the tick's core as the
    ingest does (``rebased``), the clock rate stays within 0.5 % of 1 and the producer drives
    every tick (the stall is shorter than ``hold``). Before the rate's baseline started over at
    a re-anchor, the step was taken for a slope: the rate went to 0.90-0.94 (the bound 0.90)
    and the read ran up to 10 % fast for seconds."""
    start, length = stall
    rng = random.Random(7)
    arrivals = []
    for n in range(int(5.0 / DT)):
        sent = n * DT
        t = 1000.0 + min(sent, 1.0) + max(0.0, sent - 2.5)
        rx = sent + 0.001 + 0.002 * rng.random()
        if start <= sent < start + length:
            rx = start + length + 0.001 + 0.00001 * n  # held, then delivered in order
        arrivals.append((t, rx))
    core = TickCore(RiderModel(scale=25.0), Timing(delay=0.03, hold=0.25), ProceduralHorse())
    clock, rates, drivers, k = ProducerClock(), [], set(), 0
    for now in np.arange(0.0, 5.0, 0.005):
        while k < len(arrivals) and arrivals[k][1] <= now:
            t, rx = arrivals[k]
            step = clock_step(clock, t, rx, JUMP, PAUSE)
            clock, k = step.clock, k + 1
            core.push_input(1, step.t, rx, [0.0] * len(HORSE_NAMES), rebased=step.rebased)
        result = core.step(float(now))
        if now > 0.1:
            drivers.add(result.driver)
            rates.append(core.resampler.rate)
    assert drivers == {Driver.INPUT}
    assert max(abs(r - 1.0) for r in rates) < 0.005, (min(rates), max(rates))
