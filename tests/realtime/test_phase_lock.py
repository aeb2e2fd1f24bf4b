"""The phase lock: locks to a steady stream and puts the deadlines just after its frames,
holds when it stops, ignores other rates and irregular streams, never slews faster than allowed."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.realtime import phase_lock as pl

TICK = 120.0
P = 1.0 / TICK


@dataclass
class Run:
    """A tick simulated the way ``TickLoop`` uses the unit: deadline n + 1 is deadline n plus
    one period plus the shift of step n; a frame is taken by the first deadline at or after it."""

    model: pl.Model
    state: pl.State
    deadlines: list[float] = field(default_factory=list)
    waits: list[tuple[float, float]] = field(default_factory=list)
    """(receive time, deadline - receive time) of every frame taken."""
    states: list[pl.State] = field(default_factory=list)


def simulate(
    arrivals: np.ndarray, seconds: float, model: pl.Model | None = None, producers: np.ndarray | None = None
) -> Run:
    model = model or pl.Model(period=P)
    origin = 0.0
    run = Run(model, pl.start(origin))
    deadline, i, n = origin, 0, len(arrivals)
    while deadline < seconds:
        deadline += model.period
        taken: list[float] = []
        producer = 1 if producers is None else -1
        while i < n and arrivals[i] <= deadline:
            taken.append(float(arrivals[i]))
            producer = 1 if producers is None else int(producers[i])
            run.waits.append((float(arrivals[i]), deadline - arrivals[i]))
            i += 1
        if producers is not None and not taken and run.states:
            producer = run.state.producer
        run.state = pl.step(model, run.state, deadline, producer, taken)
        run.deadlines.append(deadline)
        run.states.append(run.state)
        deadline += run.state.shift
    return run


def stream(rate: float, seconds: float, jitter: float, seed: int = 1, phase: float = 0.0031) -> np.ndarray:
    """Receive times of a producer at ``rate``: late by a half-normal ``jitter`` (never early)."""
    rng = np.random.default_rng(seed)
    n = int(seconds * rate)
    return phase + np.arange(n) / rate + np.abs(rng.normal(0.0, jitter, n))


def waits_after(run: Run, t: float) -> np.ndarray:
    return np.array([w for rx, w in run.waits if rx > t])


@pytest.mark.parametrize("phase", [0.0005, 0.0031, 0.0079])
def test_locks_to_a_steady_120_hz_stream_and_takes_each_frame_a_margin_after_it(phase: float) -> None:
    run = simulate(stream(120.0, 6.0, 0.0003, phase=phase), 6.0)
    state = run.state
    assert state.locked and state.locks == 1 and state.losses == 0
    # The margin is the floor or the jitter's high quantile: half-normal 0.3 ms, ~0.5-0.7 ms after the mean.
    assert run.model.margin <= state.margin < 0.0012
    assert pl.lead(run.model, state) == pytest.approx(state.margin, abs=20e-6)
    waits = waits_after(run, 3.0)
    assert np.quantile(waits, 0.99) < state.margin + 0.0008 < 0.002
    assert np.quantile(waits, 0.5) < state.margin + 0.0002
    assert waits.min() >= 0.0
    # Without the lock the same frames wait ~uniform over a period.
    assert state.slews > 0


def test_a_divisor_rate_locks_and_a_multiple_locks_on_its_harmonic() -> None:
    slow = simulate(stream(60.0, 8.0, 0.0002), 8.0)
    assert slow.state.locked and slow.state.harmonic == 1
    assert np.quantile(waits_after(slow, 5.0), 0.99) < 0.002
    fast = simulate(stream(240.0, 6.0, 0.0002), 6.0)
    assert fast.state.locked and fast.state.harmonic == 2
    # Two frames a tick: the second of each pair is taken a margin after it arrived.
    newest = [w for (rx, w) in fast.waits[1::2] if rx > 4.0]
    assert np.quantile(newest, 0.99) < 0.002


def test_follows_a_producer_clock_a_little_off_ours_but_not_one_far_off() -> None:
    """500 ppm (a cheap crystal is within 100): locked, the arrival phase followed as it
    drifts, so the frames still wait about the margin; 2000 ppm is more than ``max_drift``."""
    near = simulate(stream(TICK * (1.0 - 5e-4), 8.0, 0.0002), 8.0)
    assert near.state.locked and near.state.drift == pytest.approx(5e-4 * P * TICK, rel=0.3)
    assert np.quantile(waits_after(near, 4.0), 0.99) < 0.0015
    far = simulate(stream(TICK * (1.0 - 2e-3), 8.0, 0.0002), 8.0)
    assert not any(s.locked for s in far.states) and far.state.offset == 0.0


def test_holds_its_phase_when_the_input_stops() -> None:
    run = simulate(stream(120.0, 4.0, 0.0002), 6.0)
    locked_at = next(i for i, s in enumerate(run.states) if s.locked)
    stopped = next(i for i, d in enumerate(run.deadlines) if d > 4.0)
    assert locked_at < stopped
    assert run.states[stopped + 10].locked, "a stall shorter than the gap (0.25 s) keeps the lock"
    gone = stopped + int(run.model.gap / P) + 2
    after = run.states[gone:]
    assert all(not s.locked for s in after) and run.state.losses == 1
    assert all(s.shift == 0.0 and s.offset == after[0].offset for s in after)
    assert run.state.times == ()
    # The deadlines stay a period apart, in the phase they had.
    gaps = np.diff(run.deadlines[gone:])
    assert np.allclose(gaps, P, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    "arrivals",
    [
        stream(100.0, 6.0, 0.0002),  # another rate: its phase against a 120 Hz tick turns
        stream(117.0, 6.0, 0.0001),  # near the tick's rate, but its phase turns 3 times a second
        stream(500.0 / 3.0, 6.0, 0.0001),  # 1.39 frames a tick: no whole multiple
        np.cumsum(np.random.default_rng(3).exponential(P, 720)),  # irregular, at the tick's rate on average
        np.sort(np.random.default_rng(4).uniform(0.0, 6.0, 720)),
    ],
    ids=["100Hz", "117Hz", "167Hz", "poisson", "uniform"],
)
def test_never_locks_to_another_rate_or_an_irregular_stream(arrivals: np.ndarray) -> None:
    run = simulate(arrivals, 6.0)
    assert not any(s.locked for s in run.states)
    assert run.state.offset == 0.0 and run.state.slews == 0
    assert np.allclose(np.diff(run.deadlines), P, rtol=0, atol=1e-12)


def test_no_input_no_effect() -> None:
    run = simulate(np.array([]), 2.0)
    assert all(s._replace(producer=-1) == pl.start(0.0) for s in run.states)
    assert np.allclose(np.diff(run.deadlines), P, rtol=0, atol=1e-12)


def test_follows_the_driving_producer_only() -> None:
    """Two producers whose frames alternate (a handover back and forth) never make a lock:
    a new producer empties the window; a steady one afterwards locks on its own."""
    arrivals = stream(120.0, 6.0, 0.0002)
    producers = np.where(np.arange(len(arrivals)) % 20 < 10, 1, 2)
    run = simulate(arrivals, 6.0, producers=producers)
    assert not any(s.locked for s in run.states) and run.state.slews == 0
    steady = np.where(arrivals < 2.0, producers, 7)
    run = simulate(arrivals, 6.0, producers=steady)
    assert run.state.locked and run.state.producer == 7


def test_a_lock_is_let_go_when_the_rate_changes() -> None:
    first = stream(120.0, 4.0, 0.0002)
    second = 4.0 + stream(100.0, 4.0, 0.0002, seed=2)
    run = simulate(np.concatenate([first, second]), 8.0)
    assert any(s.locked for s in run.states[: int(4.0 * TICK)])
    assert not run.state.locked and run.state.losses == 1


def test_the_model_refuses_impossible_parameters() -> None:
    with pytest.raises(ValueError, match="margin"):
        pl.Model(period=P, margin=P)
    with pytest.raises(ValueError, match="slew"):
        pl.Model(period=P, slew=0.5)
    with pytest.raises(ValueError, match="resultant"):
        pl.Model(period=P, lock_resultant=0.5, unlock_resultant=0.7)


segments = st.lists(
    st.tuples(
        st.floats(20.0, 1000.0),  # producer rate, Hz
        st.floats(0.0, 0.003),  # jitter, s
        st.floats(0.05, 2.0),  # duration, s
        st.integers(1, 3),  # producer id
        st.floats(0.0, 0.5),  # silence after it, s
    ),
    min_size=1,
    max_size=5,
)


@settings(max_examples=40, deadline=None)
@given(segments=segments, tick=st.sampled_from([60.0, 120.0, 500.0]), seed=st.integers(0, 2**16))
def test_the_deadlines_never_move_by_more_than_the_slew(
    segments: list[tuple[float, float, float, int, float]], tick: float, seed: int
) -> None:
    rng = np.random.default_rng(seed)
    times, ids, t = [], [], 0.0
    for rate, jitter, duration, producer, silence in segments:
        n = max(1, int(duration * rate))
        times.append(t + np.arange(n) / rate + np.abs(rng.normal(0.0, jitter, n)))
        ids.append(np.full(n, producer))
        t += duration + silence
    order = np.argsort(np.concatenate(times), kind="stable")
    arrivals, producers = np.concatenate(times)[order], np.concatenate(ids)[order]
    model = pl.Model(period=1.0 / tick)
    run = simulate(arrivals, t + 0.2, model, producers)
    bound = model.slew * model.period
    assert all(abs(s.shift) <= bound for s in run.states)
    gaps = np.diff(run.deadlines)
    assert gaps.min() >= (1.0 - model.slew) * model.period - 1e-12
    assert gaps.max() <= (1.0 + model.slew) * model.period + 1e-12
    assert all(s.shift == 0.0 for s in run.states if not s.locked)
    assert all(math.isnan(s.margin) or model.margin <= s.margin <= 0.5 * model.period for s in run.states)
    # Each step moves by at most the slew, and only the phase: the offset is the sum of the shifts.
    assert run.state.offset == pytest.approx(sum(s.shift for s in run.states), abs=1e-9)
