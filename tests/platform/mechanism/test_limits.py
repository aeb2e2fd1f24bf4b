"""The safety stage: soft limits, speed and acceleration for any targets and frame times; the eased moves."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.platform.mechanism import limits as L
from riderlive.platform.mechanism.limits import SafetyModel, SafetyState

LOWER, UPPER = np.array([0.005, 0.005, -58.0]), np.array([0.245, 0.245, 58.0])
VMAX, AMAX = np.array([0.8, 0.5, 400.0]), np.array([20.0, 8.0, 8000.0])
MODEL = SafetyModel(LOWER, UPPER, VMAX, AMAX)


def check_limits(start: np.ndarray, out: np.ndarray, dt: np.ndarray) -> None:
    """Every command within the soft limits; its speed and its change of speed within the limits."""
    assert np.all(out >= LOWER - 1e-12) and np.all(out <= UPPER + 1e-12)
    q = np.vstack([start, out])
    v = np.diff(q, axis=0) / dt[:, None]
    assert np.all(np.abs(v) <= VMAX * (1 + 1e-9) + 1e-12)
    a = np.diff(np.vstack([np.zeros(3), v]), axis=0) / dt[:, None]
    assert np.all(np.abs(a) <= AMAX * (1 + 1e-9) + 1e-9)


targets = st.lists(
    st.tuples(
        st.one_of(st.floats(-0.5, 0.8), st.just(math.nan), st.just(math.inf)),
        st.floats(-0.5, 0.8),
        st.floats(-120.0, 120.0),
        st.floats(0.0005, 0.05),
    ),
    min_size=1,
    max_size=300,
)


@settings(max_examples=150, deadline=None)
@given(frames=targets)
def test_any_targets_any_frame_times_stay_within_every_limit(frames: list[tuple[float, float, float, float]]) -> None:
    q = np.array([f[:3] for f in frames])
    dt = np.array([f[3] for f in frames])
    start = np.array([0.125, 0.125, 0.0])
    _state, out = L.run(MODEL, SafetyState.at(start), q, dt)
    check_limits(start, out, dt)
    assert np.all(np.isfinite(out))


def test_targets_within_the_limits_are_followed_exactly() -> None:
    t = np.arange(1200) / 120.0
    # starting at rest (a sine would start at full speed: an infinite acceleration from rest)
    q = np.column_stack(
        [0.1 + 0.05 * (1 - np.cos(2 * math.pi * 2.0 * t)), 0.125 + 0.01 * np.sin(3 * t) ** 2, 20 * (1 - np.cos(t))]
    )
    state, out = L.run(MODEL, SafetyState.at(q[0]), q, 1 / 120.0)
    np.testing.assert_allclose(out, q, atol=1e-12)
    assert state.counters == dict.fromkeys(L.COUNTERS, 0)


def test_a_one_frame_spike_is_filtered() -> None:
    q = np.full((240, 3), [0.125, 0.125, 0.0])
    q[100] = [0.245, 0.245, 58.0]  # a dropped-byte jump to the far end for one frame
    dt = 1 / 120.0
    state, out = L.run(MODEL, SafetyState.at(q[0]), q, dt)
    moved = np.abs(out - q[0]).max(axis=0)
    assert np.all(moved <= AMAX * dt * dt * 1.01)  # one frame at full acceleration, then braking
    np.testing.assert_allclose(out[-1], q[0], atol=1e-12)
    assert state.counters["accel_limited_frames"] >= 1


def test_soft_limits_and_non_finite_targets_are_counted() -> None:
    q = np.array([[0.3, 0.125, 0.0], [np.nan, 0.125, 0.0], [0.125, 0.125, 70.0]])
    state, out = L.run(MODEL, SafetyState.at([0.125, 0.125, 0.0]), q, 1 / 120.0)
    c = state.counters
    assert c["soft_limit_frames"] == 2 and c["nan_targets"] == 1
    assert np.all(np.isfinite(out))


def test_a_stop_at_the_limit_never_passes_it() -> None:
    """The target runs into the upper limit at speed and stops there: following it would overshoot,
    the braking bound starts slowing down early enough to stop on the limit."""
    dt = 1 / 500.0
    t = np.arange(600) * dt
    q = np.column_stack([0.005 + 0.7 * t, 0.005 + 0.45 * t, -58.0 + 350.0 * t])
    q = np.minimum(q, [0.3, 0.3, 70.0])  # and on past the soft limits (clipped)
    start = np.array([0.005, 0.005, -58.0])
    state, out = L.run(MODEL, SafetyState.at(start), q, dt)
    check_limits(start, out, np.full(600, dt))
    np.testing.assert_allclose(out[-1], UPPER, atol=1e-9)
    assert state.counters["braking_frames"] > 0 and state.counters["soft_limit_frames"] > 0


def test_step_and_run_and_the_python_source_agree() -> None:
    rng = np.random.default_rng(4)
    q = np.array([0.125, 0.125, 0.0]) + rng.normal(0, 1, (300, 3)) * np.array([0.05, 0.05, 20.0])
    dt = rng.uniform(0.002, 0.02, 300)
    batch_state, batch = L.run(MODEL, SafetyState.at(q[0]), q, dt)
    state = SafetyState.at(q[0])
    s = list(state.values)
    for k in range(300):
        state, out = L.step(MODEL, state, q[k], float(dt[k]))
        assert np.array_equal(out, batch[k])
        py = [0.0] * 3
        L.follow_frame(LOWER.tolist(), UPPER.tolist(), VMAX.tolist(), AMAX.tolist(), s, q[k].tolist(), float(dt[k]), py)
        np.testing.assert_allclose(py, batch[k], atol=1e-12)
    assert np.array_equal(state.values, batch_state.values)


def test_zero_frame_time_holds() -> None:
    _state, out = L.step(MODEL, SafetyState.at([0.1, 0.1, 0.0]), [0.2, 0.2, 10.0], 0.0)
    np.testing.assert_array_equal(out, [0.1, 0.1, 0.0])


# ------------------------------------------------------------------ eased moves


def test_ease_shape() -> None:
    assert L.ease(0.0) == 0.0 and L.ease(1.0) == 1.0 and L.ease(0.5) == 0.5
    assert L.ease(-1.0) == 0.0 and L.ease(2.0) == 1.0
    u = np.linspace(0, 1, 10001)
    e = np.array([L.ease(x) for x in u])
    assert np.all(np.diff(e) >= 0.0)
    slope = np.gradient(e, u)
    assert slope.max() == pytest.approx(L.PEAK_SPEED, rel=1e-4)
    assert np.abs(np.gradient(slope, u)).max() == pytest.approx(L.PEAK_ACCEL, rel=1e-3)
    assert L.eased([0.0, 10.0], [1.0, 0.0], 1.5, 3.0) == [0.5, 5.0]
    assert L.eased([0.0], [1.0], 0.0, 0.0) == [1.0]


@settings(max_examples=60, deadline=None)
@given(
    start=st.tuples(st.floats(0.005, 0.245), st.floats(0.005, 0.245), st.floats(-58.0, 58.0)),
    goal=st.tuples(st.floats(0.005, 0.245), st.floats(0.005, 0.245), st.floats(-58.0, 58.0)),
    seconds=st.floats(1.0, 5.0),
)
def test_an_eased_park_long_enough_needs_no_limiting(
    start: tuple[float, float, float], goal: tuple[float, float, float], seconds: float
) -> None:
    need = L.ease_seconds(start, goal, VMAX, AMAX)
    seconds = max(seconds, need)
    rate = 500.0
    track = L.eased_track(start, goal, seconds, rate)
    np.testing.assert_allclose(track[0], start, atol=0) and np.testing.assert_allclose(track[-1], goal, atol=1e-12)
    state, out = L.run(MODEL, SafetyState.at(start), track[1:], 1 / rate)
    check_limits(np.array(start), out, np.full(len(out), 1 / rate))
    np.testing.assert_allclose(out, track[1:], atol=1e-9)  # the follower had nothing to do
    assert state.counters["speed_limited_frames"] == 0


def test_parking_while_moving_eases_down_within_the_limits() -> None:
    """Park requested mid-motion: the eased target starts where the command is, the follower first
    brakes the speed it had; the platform arrives at park and stays there."""
    t = np.arange(240) / 120.0
    running = np.column_stack([0.125 + 0.08 * np.sin(2 * math.pi * 1.5 * t), np.full(240, 0.2), 30 * np.sin(4 * t)])
    state, out = L.run(MODEL, SafetyState.at(running[0]), running, 1 / 120.0)
    park = [0.01, 0.01, -40.0]
    track = L.eased_track(out[-1], park, 3.0, 120.0)
    state, parked = L.run(MODEL, state, track[1:], 1 / 120.0)
    check_limits(running[0], np.vstack([out, parked]), np.full(240 + len(parked), 1 / 120.0))
    np.testing.assert_allclose(parked[-1], park, atol=1e-6)
