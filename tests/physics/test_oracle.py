"""The compiled single-source physics against the previous NumPy implementation (the oracle), and against
its own source run uncompiled: per step, over whole takes, and on random strands.

Tolerance: 1e-12 per step (metres, unit-vector components, radians turned per step),
from the same state; 1e-9 m running free over a whole take (rounding differences
may grow, but stay tiny).
"""

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
from riderlive.physics import attach, chain, collision, reference, skinned, strands
from riderlive.physics.attach import HINDQUARTERS, Body
from riderlive.physics.config import PhysicsConfig
from riderlive.physics.drive import Drive, TakeSource
from riderlive.physics.reference import ReferenceModel
from riderlive.physics.skinned import SkinnedModel, SkinnedState
from riderlive.physics.strands import StrandModel, StrandState
from riderlive.rules.engine import RiderModel
from riderlive.rules.params import load_preset
from tests.physics import numpy_oracle as oracle
from tests.physics.motion import horse_take, source
from tests.physics.test_chain import hanging_chain
from tests.physics.test_chain import model as chain_model
from tests.physics.test_strands import _shapes

CONFIG = PhysicsConfig()
DT = 1.0 / CONFIG.rate
TOL = 1e-12


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


class OracleSkinned:
    """The previous skinned step: NumPy posing, strand step and chains, on the same model."""

    def __init__(self, model: SkinnedModel) -> None:
        self.model = model
        self.posing = oracle.Posing(CONFIG.horse, CONFIG.rider)
        cloth = CONFIG.rider.cloth.root_length
        self.roots = (CONFIG.skinned.strand.root_length, CONFIG.rider.braid.root_length, cloth, cloth)

    def step(self, state: SkinnedState, drive: Drive) -> SkinnedState:
        pins, up, colliders, hq, head, hips = self.posing.anchors(drive.horse, drive.rider, *self.roots)
        moved = oracle.strand_step(self.model.strands, state.strands, pins, colliders)
        bones = oracle.chain_step(self.model.bones, state.bones, moved.x, up)
        return SkinnedState(moved, bones, (hq, head, hips, hips))


@cache
def _compare_take(kind: str) -> tuple[dict[str, float], float, float]:
    """Per step: both from the oracle's state; also the compiled path running free, and the anchors."""
    fast = SkinnedModel.build(CONFIG)
    slow = OracleSkinned(fast)
    src = _with_rider(kind)
    steps = len(horse_take(kind)[0]) - 1
    state = free = fast.initial(src(0.0))
    worst = dict.fromkeys(_differences(state, state), 0.0)
    drift = anchors = 0.0
    for k in range(1, steps + 1):
        drive = src(k * DT)
        got = fast.anchors(drive)
        pins, up, caps, _, _, _ = slow.posing.anchors(drive.horse, drive.rider, *slow.roots)
        for u, v in ((got.pins, pins), (got.up, up), (got.colliders.a, caps.a), (got.colliders.b, caps.b)):
            anchors = max(anchors, float(np.abs(u - v).max()))
        assert np.array_equal(got.colliders.radius, caps.radius)
        expected = slow.step(state, drive)
        for name, value in _differences(expected, fast.step(state, drive)).items():
            worst[name] = max(worst[name], value)
        free = fast.step(free, drive)
        drift = max(drift, float(np.abs(free.strands.x - expected.strands.x).max()))
        state = expected
    return worst, drift, anchors


@pytest.mark.parametrize("kind", ["gallop", "buck"])
def test_skinned_step_agrees_with_the_oracle_every_step(kind: str) -> None:
    worst, _, anchors = _compare_take(kind)
    assert anchors <= TOL
    assert max(worst.values()) <= TOL, worst


@pytest.mark.parametrize("kind", ["gallop", "buck"])
def test_skinned_take_stays_on_the_oracle_take(kind: str) -> None:
    _, drift, _ = _compare_take(kind)
    assert drift <= 1e-9


def test_posing_without_a_rider_and_by_channel_name() -> None:
    body, slow = Body(CONFIG.horse, CONFIG.rider), oracle.Posing(CONFIG.horse, CONFIG.rider)
    src = source("buck")
    for t in np.linspace(0.0, 3.5, 50):
        horse = src(t).horse
        pose = body.pose(horse)
        hq = slow.hindquarters(horse)
        caps = slow.colliders(horse, hq)
        np.testing.assert_allclose(pose.frame(HINDQUARTERS).origin, hq.origin, rtol=0.0, atol=TOL)
        np.testing.assert_allclose(pose.frame(HINDQUARTERS).rotation, hq.rotation, rtol=0.0, atol=TOL)
        np.testing.assert_allclose(pose.frame(attach.DOCK).origin, slow.dock(hq).origin, rtol=0.0, atol=TOL)
        np.testing.assert_allclose(pose.horse_colliders.a, caps.a, rtol=0.0, atol=TOL)
        np.testing.assert_allclose(pose.horse_colliders.b, caps.b, rtol=0.0, atol=TOL)
    # The kernel reads channels by the indices resolved from their names once.
    assert attach.HORSE.rearPivot_rz == HORSE_NAMES.index("rearPivot.rz")
    assert attach.RIDER.lower_back_rz == list(attach.RIDER_INDEX).index("lower_back.rz")


def test_reference_step_agrees_with_the_oracle() -> None:
    """400 strands: the compiled solver now runs the reference tail too."""
    ref = ReferenceModel.build(CONFIG)
    slow = oracle.Posing(CONFIG.horse, CONFIG.rider)
    src = source("gallop")
    state = ref.initial(src(0.0))
    worst = 0.0
    for k in range(1, 61):
        drive = src(k * DT)
        hq = slow.hindquarters(drive.horse)
        pins = reference.pinned_vertices(slow.dock(hq), ref.root_offsets, CONFIG.reference.strand.root_length)
        expected = oracle.strand_step(ref.strands, state, pins, slow.colliders(drive.horse, hq))
        got = ref.step(state, drive)
        worst = max(worst, float(np.abs(got.x - expected.x).max()), float(np.abs(got.x_prev - expected.x_prev).max()))
        state = expected
    assert worst <= TOL


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
def test_strand_step_matches_the_oracle_on_random_strands(
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
        expected = oracle.strand_step(model, state, pins, caps)
        got = strands.step(model, state, pins, caps)
        assert np.allclose(got.x, expected.x, rtol=0.0, atol=TOL)
        assert np.allclose(got.x_prev, expected.x_prev, rtol=0.0, atol=TOL)


def test_chain_matches_the_oracle_under_twist_and_swing() -> None:
    """The spin of test_chain plus a swinging strand: torsion, fan-out and folded joints all active."""
    x0 = hanging_chain()
    m = chain_model()
    anchor = np.array([[1.0], [0.0], [0.0]])
    state = chain.rest_state(x0, anchor)
    rest = oracle.chain_rest_state(x0, anchor)
    assert np.allclose(state.up, rest.up, rtol=0.0, atol=TOL) and np.allclose(state.axis, rest.axis, rtol=0, atol=TOL)
    for k in range(1, 481):
        phi = 1.5 * k * DT
        up = np.array([[math.cos(phi)], [0.0], [math.sin(phi)]])
        x = x0.copy()
        x[1:, 0, 0] += 0.3 * math.sin(5.0 * k * DT) * np.arange(1, 12) / 11
        x[-3:, 1, 0] += 0.3 * (k % 60 > 50)  # sometimes fold the tip back on itself
        expected = oracle.chain_step(m, state, x, up)
        got = chain.step(m, state, x, up)
        for u, v in zip((expected.axis, expected.up, expected.fan), (got.axis, got.up, got.fan)):
            assert np.allclose(u, v, rtol=0.0, atol=TOL)
        assert np.allclose(expected.twist_velocity * DT, got.twist_velocity * DT, rtol=0.0, atol=TOL)
        state = expected
    assert state.fan.max() > 0.0


def test_one_source_runs_compiled_and_interpreted_alike() -> None:
    """The fused skinned step's source, run by the Python interpreter, gives the compiled numbers (to rounding)."""
    model = SkinnedModel.build(CONFIG)
    src = _with_rider("buck")
    state = model.initial(src(0.0))
    for k in range(1, 200):  # into the buck: collisions and torsion at work
        state = model.step(state, src(k * DT))
    drive = src(200 * DT)
    args = (
        state.strands.x, state.strands.x_prev, state.bones.axis, state.bones.up, state.bones.fan,
        drive.horse, drive.rider, *model._constants,
    )  # fmt: skip
    compiled = skinned.advance(*args)
    interpreted = _interpreted(skinned.advance.py_func, *args)
    for u, v in zip(compiled, interpreted, strict=True):
        np.testing.assert_allclose(u, v, rtol=0.0, atol=TOL)


def _interpreted(fn, *args):  # type: ignore[no-untyped-def]
    """Call ``fn`` with every kernel it reaches swapped for its Python source."""
    modules = (attach, chain, collision, skinned, strands)
    saved = []
    for module in modules:
        for name, value in list(vars(module).items()):
            if hasattr(value, "py_func") and getattr(value, "__module__", "").startswith("riderlive.physics"):
                saved.append((module, name, value))
                setattr(module, name, value.py_func)
    try:
        return fn(*args)
    finally:
        for module, name, value in saved:
            setattr(module, name, value)


def test_each_kernel_compiles_once_for_the_live_step() -> None:
    _compare_take("buck")
    for kernel in (skinned.advance, attach.pose, skinned.anchor_pins):
        assert len(kernel.signatures) == 1, kernel  # type: ignore[attr-defined]


def test_tail_command_matches_the_oracle_take(tmp_path: Path) -> None:
    """``riderlive tail`` end to end: its bone positions equal the oracle's strands on the same take."""
    times, frames = horse_take("buck")
    take = tmp_path / "buck.csv"
    write_frames(str(take), FrameTable(HORSE_NAMES, frames[:240:4], times[:240:4]))
    out = tmp_path / "tail.csv"
    assert main(["tail", str(take), "-o", str(out), "--no-rider"]) == 0
    table = np.loadtxt(out, delimiter=",", skiprows=1)
    assert table.shape[0] == 60 and np.isfinite(table).all()
    src = TakeSource(times[:240:4], frames[:240:4])
    fast = SkinnedModel.build(CONFIG)
    slow = OracleSkinned(fast)
    state = fast.initial(src(0.0))
    for k in range(1, round(times[236] * CONFIG.rate) + 1):
        state = slow.step(state, src(k * DT))
    header = out.read_text().splitlines()[0].split(",")
    tip = [header.index(f"tail_10.{a}") for a in ("tx", "ty", "tz")]
    np.testing.assert_allclose(table[-1, tip], state.strands.x[10, :, 0], rtol=0.0, atol=1e-8)
