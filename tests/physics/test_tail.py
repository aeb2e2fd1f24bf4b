"""The tails and the braid on procedural horse takes: lengths, collisions, rate independence, agreement."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np
import pytest

from riderlive.horse import DEFAULT_SCALE, ProceduralHorse
from riderlive.physics.attach import HINDQUARTERS
from riderlive.physics.collision import Capsules, depth
from riderlive.physics.config import PhysicsConfig
from riderlive.physics.drive import Drive, FixedStepper, LiveSource
from riderlive.physics.reference import ReferenceModel, mean_tip
from riderlive.physics.skinned import BRAID, TAIL, SkinnedModel
from riderlive.physics.strands import stretch
from riderlive.rules.engine import RiderModel
from riderlive.rules.params import load_preset
from tests.physics.motion import horse_take, source, standing

CONFIG = PhysicsConfig()


@dataclass
class Run:
    ref_stretch: float
    ref_depth: float
    tail_stretch: float
    braid_stretch: float
    skinned_depth: float
    tail_tip: np.ndarray  # (F, 3) skinned tail tip in the hindquarters frame, 60 Hz
    mean_tip: np.ndarray  # (F, 3) mean tip of the reference strands, same frame


@cache
def run(kind: str) -> Run:
    """Both tails (and the braid) on a take, checked after every internal step."""
    src = standing if kind == "standing" else source(kind)
    duration = 1.5 if kind == "standing" else float(horse_take(kind)[0][-1])
    ref, sk = ReferenceModel.build(CONFIG), SkinnedModel.build(CONFIG)
    r = FixedStepper(ref.step, ref.initial(src(0.0)), CONFIG.rate)
    s = FixedStepper(sk.step, sk.initial(src(0.0)), CONFIG.rate)
    out = Run(0.0, -1.0, 0.0, 0.0, -1.0, np.zeros(0), np.zeros(0))
    tips, means = [], []
    while r.steps < duration * CONFIG.rate:
        t = r.time + 1.0 / CONFIG.rate
        r.advance_to(t, src)
        s.advance_to(t, src)
        drive = src(r.time)
        pose = ref.body.pose(drive.horse)
        hq = pose.frame(HINDQUARTERS)
        if kind != "trot_rear_gallop":  # its reference is only compared, not checked
            out.ref_stretch = max(out.ref_stretch, float(stretch(ref.strands, r.state.x).max()))
            out.ref_depth = max(out.ref_depth, float(depth(r.state.x[2:], pose.horse_colliders).max()))
        st = stretch(sk.strands, s.state.strands.x)
        out.tail_stretch = max(out.tail_stretch, float(st[:, TAIL].max()))
        out.braid_stretch = max(out.braid_stretch, float(st[:, BRAID].max()))
        out.skinned_depth = max(
            out.skinned_depth, float(depth(s.state.strands.x[2:], sk.anchors(drive).colliders).max())
        )
        if r.steps % 4 == 0:
            tips.append(hq.rotation.T @ (s.state.strands.x[-1, :, TAIL] - hq.origin))
            means.append(hq.rotation.T @ (mean_tip(r.state) - hq.origin))
    out.tail_tip, out.mean_tip = np.array(tips), np.array(means)
    return out


def test_reference_at_rest_keeps_lengths_within_1_percent() -> None:
    assert run("standing").ref_stretch <= 0.01
    assert run("standing").tail_stretch <= 0.01


@pytest.mark.parametrize("kind", ["gallop", "buck"])
def test_reference_keeps_lengths_within_5_percent_and_stays_outside_the_body(kind: str) -> None:
    result = run(kind)
    assert result.ref_stretch <= 0.05
    assert result.ref_depth <= 0.0


@pytest.mark.parametrize("kind", ["gallop", "buck", "trot_rear_gallop"])
def test_skinned_strand_keeps_lengths_within_1_percent(kind: str) -> None:
    result = run(kind)
    assert result.tail_stretch <= 0.01
    assert result.braid_stretch <= 0.05  # the braid, resting on the back, is pushed after the length pass
    assert result.skinned_depth <= 0.0


def test_skinned_chain_follows_the_reference() -> None:
    """Tip paths in the hindquarters frame over trot -> rear -> gallop: Pearson r >= 0.9 on each axis that moves."""
    result = run("trot_rear_gallop")
    a, b = result.tail_tip, result.mean_tip
    for axis in range(3):
        if b[:, axis].std() > 0.02:
            assert np.corrcoef(a[:, axis], b[:, axis])[0, 1] >= 0.9, axis
    da, db = (a - a.mean(0)).ravel(), (b - b.mean(0)).ravel()
    assert da @ db / np.linalg.norm(da) / np.linalg.norm(db) >= 0.9


def _states_at_common_times(tick: float, seconds: float) -> list[tuple[np.ndarray, ...]]:
    config = PhysicsConfig.model_validate({"reference": {"strands": 16}})
    horse = ProceduralHorse("canter")
    rules = RiderModel(params=load_preset("kuhnel2003"), scale=DEFAULT_SCALE)
    src = LiveSource(_Replay(horse), rules)
    sk, ref = SkinnedModel.build(config), ReferenceModel.build(config)
    s = FixedStepper(sk.step, sk.initial(src(0.0)), config.rate)
    r = FixedStepper(ref.step, ref.initial(src(0.0)), config.rate)
    found = []
    for k in range(1, round(seconds * tick) + 1):
        t = k / tick
        s.advance_to(t, src)
        r.advance_to(t, src)
        if (k * 6) % round(tick) == 0:  # t is a multiple of 1/6 s: common to 30, 60, 120 and 144 Hz
            st = s.state
            found.append((st.strands.x, st.strands.x_prev, st.bones.up, st.bones.fan, r.state.x, r.state.x_prev))
    return found


class _Replay:
    """A live horse shared by two steppers: frames cached by time, since a live horse only moves forward."""

    def __init__(self, horse: ProceduralHorse) -> None:
        self.horse = horse
        self.frames: dict[float, list[float]] = {}

    def sample(self, t: float) -> list[float]:
        if t not in self.frames:
            self.frames[t] = self.horse.sample(t)
        return self.frames[t]


def test_same_input_at_any_tick_rate_gives_identical_states() -> None:
    runs = {rate: _states_at_common_times(rate, 1.0) for rate in (30.0, 60.0, 120.0, 144.0)}
    assert all(len(v) == 6 for v in runs.values())
    for rate in (60.0, 120.0, 144.0):
        for a, b in zip(runs[30.0], runs[rate], strict=True):
            for x, y in zip(a, b, strict=True):
                assert np.array_equal(x, y)


def test_take_source_interpolates_and_holds_the_ends() -> None:
    times, frames = horse_take("gallop")
    src = source("gallop")
    mid = src(0.5 * (times[10] + times[11])).horse
    assert np.allclose(mid, 0.5 * (frames[10] + frames[11]))
    assert np.array_equal(src(-1.0).horse, frames[0]) and np.array_equal(src(1e9).horse, frames[-1])


def test_collision_shapes_follow_the_horse() -> None:
    ref = ReferenceModel.build(CONFIG)
    drive: Drive = source("buck")(2.0)
    caps: Capsules = ref.body.pose(drive.horse).horse_colliders
    assert len(caps) == 3
    assert np.all(caps.b[1:, 1] < caps.a[1:, 1])  # legs run down from the hips toward the hooves


def test_bad_drive_holds_the_last_good_one_and_a_stall_is_skipped() -> None:
    sk = SkinnedModel.build(CONFIG)
    good = source("gallop")

    def flaky(t: float) -> Drive:
        drive = good(t)
        if 0.5 <= t < 0.6:
            horse = drive.horse.copy()
            horse[0] = np.nan
            return Drive(horse)
        return drive

    stepper = FixedStepper(sk.step, sk.initial(good(0.0)), CONFIG.rate, max_catch_up=48)
    for k in range(1, 61):
        stepper.advance_to(k / 60.0, flaky)
    assert stepper.bad_inputs == 24  # 0.1 s of 240 Hz steps
    assert np.isfinite(stepper.state.strands.x).all()
    taken = stepper.advance_to(30.0, good)  # the caller stalled for 29 s
    assert taken == 48 and stepper.skipped_steps > 6000
    assert abs(stepper.time - 30.0) < 1e-6
