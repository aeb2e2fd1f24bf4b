"""The compiled kernels against the NumPy path (the oracle): per step, over whole takes, and on random input."""

from __future__ import annotations

import math
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.channels import HORSE_NAMES
from riderlive.cli import main
from riderlive.framefile import FrameTable, write_frames
from riderlive.horse import DEFAULT_SCALE
from riderlive.physics import chain, kernels, strands
from riderlive.physics.config import PhysicsConfig
from riderlive.physics.drive import TakeSource
from riderlive.physics.skinned import SkinnedModel, SkinnedState
from riderlive.physics.strands import StrandModel, StrandState
from riderlive.rules.engine import RiderModel
from riderlive.rules.params import load_preset
from tests.physics.motion import horse_take, source
from tests.physics.test_chain import hanging_chain
from tests.physics.test_chain import model as chain_model
from tests.physics.test_strands import _shapes

pytestmark = pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not installed")
CONFIG = PhysicsConfig()
DT = 1.0 / CONFIG.rate
TOL = 1e-12
"""Metres (positions), unit-vector components, radians per step."""


def _differences(a: SkinnedState, b: SkinnedState) -> dict[str, float]:
    """Largest absolute difference per quantity; twist velocities as the angle turned in one step."""
    pairs = {
        "x": (a.strands.x, b.strands.x),
        "x_prev": (a.strands.x_prev, b.strands.x_prev),
        "axis": (a.bones.axis, b.bones.axis),
        "up": (a.bones.up, b.bones.up),
        "twist per step": (a.bones.twist_velocity * DT, b.bones.twist_velocity * DT),
        "fan": (a.bones.fan, b.bones.fan),
        "parent origins": (np.stack([p.origin for p in a.parents]), np.stack([p.origin for p in b.parents])),
        "parent rotations": (np.stack([p.rotation for p in a.parents]), np.stack([p.rotation for p in b.parents])),
    }
    return {k: float(np.abs(u - v).max()) for k, (u, v) in pairs.items()}


def _with_rider(kind: str) -> TakeSource:
    """The take with the rider rules' frames, so the braid's anchor leans, lifts and turns."""
    times, frames = horse_take(kind)
    rules = RiderModel(params=load_preset("kuhnel2003"), scale=DEFAULT_SCALE)
    return TakeSource(times, frames, np.asarray(rules.evaluate_batch(frames), dtype=np.float64))


@cache
def _compare_take(kind: str) -> tuple[dict[str, float], float, float]:
    """Per step: both paths from the NumPy state; also the compiled path running free, and its anchors."""
    oracle = SkinnedModel.build(CONFIG, compiled=False)
    fast = SkinnedModel.build(CONFIG, compiled=True)
    src = _with_rider(kind)
    steps = len(horse_take(kind)[0]) - 1
    state = oracle.initial(src(0.0))
    free = fast.initial(src(0.0))
    worst = dict.fromkeys(_differences(state, state), 0.0)
    drift = anchors = 0.0
    for k in range(1, steps + 1):
        drive = src(k * DT)
        a, b = oracle.anchors(drive), fast.anchors(drive)
        for u, v in ((a.pins, b.pins), (a.up, b.up), (a.colliders.a, b.colliders.a), (a.colliders.b, b.colliders.b)):
            anchors = max(anchors, float(np.abs(u - v).max()))
        assert np.array_equal(a.colliders.radius, b.colliders.radius)
        expected = oracle.step(state, drive)
        for name, value in _differences(expected, fast.step(state, drive)).items():
            worst[name] = max(worst[name], value)
        free = fast.step(free, drive)
        drift = max(drift, float(np.abs(free.strands.x - expected.strands.x).max()))
        state = expected
    return worst, drift, anchors


@pytest.mark.parametrize("kind", ["gallop", "buck"])
def test_compiled_step_agrees_with_numpy_every_step(kind: str) -> None:
    worst, _, anchors = _compare_take(kind)
    assert anchors <= TOL
    assert max(worst.values()) <= TOL, worst


def test_compiled_anchors_without_a_rider() -> None:
    oracle = SkinnedModel.build(CONFIG, compiled=False)
    fast = SkinnedModel.build(CONFIG, compiled=True)
    src = source("buck")
    for t in np.linspace(0.0, 3.5, 50):
        a, b = oracle.anchors(src(t)), fast.anchors(src(t))
        for u, v in ((a.pins, b.pins), (a.up, b.up), (a.colliders.a, b.colliders.a), (a.colliders.b, b.colliders.b)):
            assert np.allclose(u, v, rtol=0.0, atol=TOL)


@pytest.mark.parametrize("kind", ["gallop", "buck"])
def test_compiled_take_stays_on_the_numpy_take(kind: str) -> None:
    """Running free over the whole take (rounding differences may grow, but stay tiny)."""
    _, drift, _ = _compare_take(kind)
    assert drift <= 1e-9


@settings(max_examples=25, deadline=None)
@given(
    st.integers(2, 14),
    st.integers(1, 4),
    st.integers(1, 3),
    st.integers(1, 4),
    st.floats(0.0, 0.5),
    st.booleans(),
    st.integers(0, 2**32 - 1),
)
def test_strand_step_matches_numpy_on_random_strands(
    vertices: int, n: int, pinned: int, iterations: int, bend: float, each: bool, seed: int
) -> None:
    pinned = min(pinned, vertices)
    rng = np.random.default_rng(seed)
    model = StrandModel(
        rest=rng.uniform(0.04, 0.1, (vertices - 1, n)),
        inv_mass=rng.uniform(0.5, 2.0, (vertices, n)),
        bend=rng.uniform(0.0, bend, n),
        pinned=pinned,
        iterations=iterations,
        damping=rng.uniform(0.0, 2.0, n),
        collision_passes=4,
        collide_each_iteration=each,
    )
    directions = rng.normal(size=(3, n))
    directions /= np.linalg.norm(directions, axis=0)
    state = strands.rest_state(model, np.zeros((3, n)), directions)
    state = StrandState(state.x + rng.normal(0.0, 0.02, state.x.shape), state.x + rng.normal(0.0, 0.02, state.x.shape))
    pins = state.x[:pinned] + 0.01
    for caps in (None, _shapes()):
        expected = strands.step(model, state, pins, caps)
        got = kernels.strand_step(model, state, pins, caps)
        assert np.allclose(got.x, expected.x, rtol=0.0, atol=TOL)
        assert np.allclose(got.x_prev, expected.x_prev, rtol=0.0, atol=TOL)


def test_chain_step_matches_numpy_under_twist_and_swing() -> None:
    """The spin of test_chain plus a swinging strand: torsion, fan-out and folded joints all active."""
    x0 = hanging_chain()
    m = chain_model()
    state = chain.rest_state(x0, np.array([[1.0], [0.0], [0.0]]))
    for k in range(1, 481):
        phi = 1.5 * k * DT
        up = np.array([[math.cos(phi)], [0.0], [math.sin(phi)]])
        x = x0.copy()
        x[1:, 0, 0] += 0.3 * math.sin(5.0 * k * DT) * np.arange(1, 12) / 11
        x[-3:, 1, 0] += 0.3 * (k % 60 > 50)  # sometimes fold the tip back on itself
        expected = chain.step(m, state, x, up)
        got = kernels.chain_step(m, state, x, up)
        for u, v in zip((expected.axis, expected.up, expected.fan), (got.axis, got.up, got.fan)):
            assert np.allclose(u, v, rtol=0.0, atol=TOL)
        assert np.allclose(expected.twist_velocity * DT, got.twist_velocity * DT, rtol=0.0, atol=TOL)
        state = expected
    assert state.fan.max() > 0.0


def test_numpy_path_is_selectable_and_each_kernel_compiles_once() -> None:
    assert SkinnedModel.build(CONFIG).compiled
    assert not SkinnedModel.build(CONFIG, compiled=False).compiled
    _compare_take("buck")
    for kernel in (kernels._strand_step, kernels._chain_step, kernels._pose):
        assert len(kernel.signatures) == 1, kernel  # type: ignore[attr-defined]


def test_tail_command_numpy_flag_gives_the_same_channels(tmp_path: Path) -> None:
    times, frames = horse_take("buck")
    take = tmp_path / "buck.csv"
    write_frames(str(take), FrameTable(HORSE_NAMES, frames[:240:4], times[:240:4]))
    outputs = []
    for extra in ([], ["--numpy"]):
        out = tmp_path / f"tail{len(extra)}.csv"
        assert main(["tail", str(take), "-o", str(out), *extra]) == 0
        outputs.append(np.loadtxt(out, delimiter=",", skiprows=1))
    assert outputs[0].shape == (60, outputs[1].shape[1])
    assert np.allclose(outputs[0], outputs[1], rtol=0.0, atol=1e-8)  # metres, degrees, quaternions
