"""The strand solver's invariants: pendulum period, energy, lengths, collisions, purity."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.physics.collision import Capsules, capsule, depth, sphere
from riderlive.physics.strands import GRAVITY, StrandModel, StrandState, energy, rest_state, step, stretch

RATE = 240.0


def pendulum(length: float, angle_deg: float) -> tuple[StrandModel, StrandState]:
    model = StrandModel(rest=np.array([[length]]), inv_mass=1.0, bend=0.0, damping=0.0, iterations=1, dt=1.0 / RATE)
    th = math.radians(angle_deg)
    x = np.zeros((2, 3, 1))
    x[1, :, 0] = [length * math.sin(th), -length * math.cos(th), 0.0]
    return model, StrandState(x, x.copy())


def analytic_period(length: float, amplitude: float) -> float:
    return 2.0 * math.pi * math.sqrt(length / GRAVITY) * (1.0 + amplitude**2 / 16.0 + 11.0 * amplitude**4 / 3072.0)


@pytest.mark.parametrize(("length", "angle"), [(1.0, 10.0), (1.0, 30.0), (0.5, 45.0)])
def test_pendulum_period_matches_the_large_amplitude_formula(length: float, angle: float) -> None:
    model, state = pendulum(length, angle)
    root = np.zeros((1, 3, 1))
    angles = []
    for _ in range(int(4.0 * RATE)):
        state = step(model, state, root)
        angles.append(math.atan2(state.x[1, 0, 0], -state.x[1, 1, 0]))
    a = np.array(angles)
    up = np.nonzero((a[:-1] < 0.0) & (a[1:] >= 0.0))[0]
    crossings = (up + 1 + a[up] / (a[up] - a[up + 1])) / RATE  # linear interpolation of the zero crossing
    assert len(crossings) >= 2
    for start, stop in itertools.pairwise(crossings):
        amplitude = np.abs(a[int(start * RATE) : int(stop * RATE)]).max()
        period = stop - start
        assert abs(period / analytic_period(length, amplitude) - 1.0) < 0.005


def test_pendulum_energy_never_increases() -> None:
    model, state = pendulum(1.0, 60.0)
    root = np.zeros((1, 3, 1))
    before = energy(model, state)
    for _ in range(int(5.0 * RATE)):
        state = step(model, state, root)
        now = energy(model, state)
        assert now <= before + 1e-12
        before = now


@pytest.mark.parametrize("bend", [0.0, 0.25, 0.5])
def test_strand_energy_never_exceeds_its_start(bend: float) -> None:
    """Released from a bend-free pose with no damping and a still root: no energy is created."""
    n = 3
    model = StrandModel(rest=np.full((11, n), 0.08), inv_mass=1.0, bend=bend, pinned=1, damping=0.0)
    directions = np.array([[1.0, 0.6, 0.0], [0.0, -0.8, 0.0], [0.0, 0.0, 1.0]])
    state = rest_state(model, np.zeros((3, n)), directions)
    pins = state.x[:1].copy()
    start = energy(model, state)
    trace = []
    for _ in range(int(4.0 * RATE)):
        state = step(model, state, pins)
        trace.append(energy(model, state))
    assert max(trace) <= start + 1e-9
    assert trace[-1] < start  # and it dissipates


def test_hanging_strands_keep_their_lengths() -> None:
    n = 50
    rng = np.random.default_rng(1)
    model = StrandModel(rest=rng.uniform(0.05, 0.1, (11, n)), inv_mass=1.0, bend=rng.uniform(0, 0.5, n), pinned=2)
    directions = np.zeros((3, n))
    directions[0] = 1.0  # start horizontal, fall, swing, come to rest
    state = rest_state(model, np.zeros((3, n)), directions)
    pins = state.x[:2].copy()
    for _ in range(int(2.0 * RATE)):
        state = step(model, state, pins)
        assert stretch(model, state.x).max() <= 0.01


def test_step_is_pure() -> None:
    model = StrandModel(rest=np.full((5, 2), 0.1), inv_mass=1.0, bend=0.3, pinned=1)
    state = rest_state(model, np.zeros((3, 2)), np.array([[1.0, 0.0], [0.0, -1.0], [0.0, 0.0]]))
    x, prev = state.x.copy(), state.x_prev.copy()
    caps = sphere(np.array([0.2, -0.05, 0.0]), 0.1)
    new = step(model, state, state.x[:1] + 0.01, caps)
    assert np.array_equal(state.x, x) and np.array_equal(state.x_prev, prev)
    assert not np.shares_memory(new.x, state.x)
    again = step(model, state, state.x[:1] + 0.01, caps)
    assert np.array_equal(new.x, again.x) and np.array_equal(new.x_prev, again.x_prev)


def _shapes() -> Capsules:
    return Capsules.concat(
        sphere(np.array([0.25, -0.35, 0.0]), 0.18),
        capsule(np.array([0.1, -0.5, -0.2]), np.array([0.1, -0.5, 0.2]), 0.06),
        capsule(np.array([0.35, -0.1, 0.0]), np.array([0.6, -0.7, 0.05]), 0.05),
    )


@settings(max_examples=12, deadline=None)
@given(st.floats(-0.6, 0.6), st.floats(-0.3, 0.3), st.floats(0.0, 2.0))
def test_no_vertex_inside_a_collider_after_a_step(swing: float, side: float, speed: float) -> None:
    n = 8
    rng = np.random.default_rng(abs(hash((swing, side, speed))) % 2**32)
    model = StrandModel(rest=np.full((11, n), 0.07), inv_mass=1.0, bend=0.2, pinned=1, collision_passes=4)
    directions = np.stack(
        (np.full(n, math.cos(swing)), np.full(n, -abs(math.sin(swing)) - 0.2), rng.uniform(-0.3, 0.3, n))
    )
    directions /= np.linalg.norm(directions, axis=0)
    state = rest_state(model, np.zeros((3, n)), directions)
    caps = _shapes()
    pins = state.x[:1].copy()
    for k in range(int(0.3 * RATE)):
        pins = pins + np.array([speed, 0.0, side])[None, :, None] / RATE * math.cos(8.0 * k / RATE)
        state = step(model, state, pins, caps)
        assert depth(state.x[1:], caps).max() <= 0.0


def test_a_vertex_on_a_capsule_axis_leaves_sideways_to_the_surface() -> None:
    """No direction to push along: the vertex leaves perpendicular to the axis, to ``radius + skin`` from it."""
    from riderlive.physics.collision import SKIN, push_out

    a, b = np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]])
    x = np.array([[[0.0], [0.5], [0.0]]])  # one vertex on the axis of a vertical capsule
    deepest = push_out(x, 0, a, b, np.array([0.2]), SKIN)
    assert deepest == pytest.approx(0.2)
    assert math.hypot(x[0, 0, 0], x[0, 2, 0]) == pytest.approx(0.2 + SKIN, abs=1e-12)
    assert x[0, 1, 0] == 0.5 and depth(x, Capsules(a, b, np.array([0.2]))).max() <= 0.0
