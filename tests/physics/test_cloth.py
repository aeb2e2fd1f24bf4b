"""Section 8.9's cloth attributes drive the rider's two coat-skirt flaps (strand columns 2 and 3).

Hand checks, from ``config/physics/tail.toml`` (``[rider]`` cloth keys, ``[rider.cloth]``):
each flap is 0.4 m long, its top 8 cm (the tie) rigid with the hips; ``cloth.up`` tilts
both ties up and back by 3 deg per unit, ``cloth.side`` to the rider's right by 3 deg
per unit, each tilt within +-75 deg. A settled flap's tip therefore moves at least as
far as its tie's end does (the strand below hangs from it) and at most as far as the
whole settled flap turned rigidly with the tie.
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest

from riderlive.channels import HORSE_NAMES, RIDER_INDEX, RIDER_NAMES, Kind, lookup
from riderlive.horse import DEFAULT_SCALE
from riderlive.physics.attach import CLOTH_L as CLOTH_L_FRAME
from riderlive.physics.attach import CLOTH_R as CLOTH_R_FRAME
from riderlive.physics.attach import HIPS, Body
from riderlive.physics.collision import depth
from riderlive.physics.config import PhysicsConfig
from riderlive.physics.drive import Drive, FixedStepper, TakeSource
from riderlive.physics.outputs import channel_names, local_rotations, publish
from riderlive.physics.quaternion import to_matrix
from riderlive.physics.skinned import CLOTH_L, CLOTH_R, SkinnedModel, SkinnedState
from riderlive.physics.strands import stretch
from riderlive.rules.engine import RiderModel
from riderlive.rules.params import load_preset
from tests.physics.motion import horse_take

CONFIG = PhysicsConfig()
RIDER = CONFIG.rider
FLAP = RIDER.cloth
MODEL = SkinnedModel.build(CONFIG)
BODY = Body(CONFIG.horse, RIDER)
FLAPS = ((CLOTH_L, CLOTH_L_FRAME), (CLOTH_R, CLOTH_R_FRAME))
MIRROR = np.array([1.0, 1.0, -1.0])
SETTLE = 6.0
"""Seconds to settle: damping 2 /s leaves exp(-12) of any starting speed."""


def rider_frame(up: float = 0.0, side: float = 0.0) -> np.ndarray:
    rider = np.zeros(len(RIDER_NAMES))
    rider[RIDER_INDEX["cloth.up"]] = up
    rider[RIDER_INDEX["cloth.side"]] = side
    return rider


def drive(up: float = 0.0, side: float = 0.0) -> Drive:
    """A horse standing still, an upright rider with the given cloth attributes."""
    return Drive(np.zeros(len(HORSE_NAMES)), rider_frame(up, side))


@cache
def settled(up: float = 0.0, side: float = 0.0) -> SkinnedState:
    d = drive(up, side)
    state = MODEL.initial(d)
    for _ in range(round(SETTLE * CONFIG.rate)):
        state = MODEL.step(state, d)
    return state


def tie(up: float = 0.0, side: float = 0.0) -> np.ndarray:
    """Each flap's tie direction (3, 2: left, right) in the world (= hips) frame of a standing horse."""
    pose = BODY.pose(np.zeros(len(HORSE_NAMES)), rider_frame(up, side))
    assert np.allclose(pose.rotations[HIPS], np.eye(3))  # standing, upright: the hips frame is the world's axes
    return np.stack([pose.rotations[f][:, 0] for _, f in FLAPS], axis=1)


def angle(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(min(1.0, float(a @ b / np.linalg.norm(a) / np.linalg.norm(b)))))


def turned(v: np.ndarray, axis: int, deg: float) -> np.ndarray:
    """``v`` turned right-handedly about world axis 0 (x) or 2 (z) by ``deg``."""
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    i, j = (axis + 1) % 3, (axis + 2) % 3
    out = v.copy()
    out[i], out[j] = c * v[i] - s * v[j], s * v[i] + c * v[j]
    return out


def test_the_attributes_tilt_both_ties_by_their_gains_within_the_limit() -> None:
    rest = tie()
    np.testing.assert_allclose(rest[:, 0], rest[:, 1] * MIRROR, rtol=0.0, atol=1e-15)  # mirror images
    up = tie(up=4.0)
    side = tie(side=-2.5)
    for k in range(2):
        along = angle(rest[:2, k], up[:2, k])  # a turn about the hips' z: exact in the x-y plane
        assert along == pytest.approx(4.0 * RIDER.cloth_up_gain, abs=1e-9)
        assert up[1, k] > rest[1, k] and up[0, k] < rest[0, k]  # up and back
        across = angle(rest[1:, k], side[1:, k])  # a turn about the hips' x: exact in the y-z plane
        assert across == pytest.approx(2.5 * RIDER.cloth_side_gain, abs=1e-9)
        assert side[2, k] < rest[2, k]  # a negative side swings to the rider's left
    absurd = tie(up=1e300, side=-1e300)
    limit = RIDER.cloth_tilt_limit
    assert np.isfinite(absurd).all()
    np.testing.assert_allclose(absurd, turned(turned(rest, 0, limit), 2, -limit), rtol=0.0, atol=1e-12)


def test_at_zero_attributes_the_flaps_hang_under_gravity() -> None:
    x = settled().strands.x
    later = MODEL.step(settled(), drive()).strands.x  # (x_prev carries follow-the-leader's correction: no speed)
    speed = np.abs(later - x)[:, :, CLOTH_L:].max() * CONFIG.rate
    assert speed < 1e-4  # m/s: the flaps have settled (the tail, damped at 0.3 /s, still sways)
    for column, _ in FLAPS:
        drop = x[0, 1, column] - x[-1, 1, column]
        assert 0.95 * FLAP.length <= drop <= FLAP.length  # the tip hangs about its length below the root
        below_tie = x[-1, :, column] - x[1, :, column]  # the free part hangs almost plumb from the tie
        assert np.hypot(below_tie[0], below_tie[2]) <= 0.1 * (FLAP.length - FLAP.root_length)
    np.testing.assert_allclose(x[:, :, CLOTH_L], x[:, :, CLOTH_R] * MIRROR[None, :], rtol=0.0, atol=1e-12)


@pytest.mark.parametrize("up", [5.0, 10.0])
def test_a_positive_cloth_up_lifts_both_tips(up: float) -> None:
    rest, lifted = settled().strands.x, settled(up=up).strands.x
    tilt = up * RIDER.cloth_up_gain  # degrees, up and back about the hips' z
    for column, _ in FLAPS:
        rise = lifted[-1, 1, column] - rest[-1, 1, column]
        tie_rise = lifted[1, 1, column] - rest[1, 1, column]  # = root_length * change of the tie's y component
        d = tie()[:, column - CLOTH_L]
        assert tie_rise == pytest.approx(FLAP.root_length * (turned(d, 2, -tilt)[1] - d[1]), abs=1e-12)
        hang = rest[-1, :, column] - rest[0, :, column]
        rigid = turned(hang, 2, -tilt)[1] - hang[1]
        assert tie_rise < rise < rigid  # at 30 deg: 2.1 cm < 3.1 cm (measured) < 7.3 cm
        assert lifted[-1, 0, column] < rest[-1, 0, column]  # and back
    assert settled(up=10.0).strands.x[-1, 1, CLOTH_R] > settled(up=5.0).strands.x[-1, 1, CLOTH_R]


def test_cloth_side_swings_both_flaps_to_the_riders_right() -> None:
    side = 5.0
    tilt = side * RIDER.cloth_side_gain  # degrees to the right, about the hips' x
    rest, swung = settled().strands.x, settled(side=side).strands.x
    for column, _ in FLAPS:
        move = swung[-1, 2, column] - rest[-1, 2, column]
        tie_move = swung[1, 2, column] - rest[1, 2, column]
        hang = rest[-1, :, column] - rest[0, :, column]
        rigid = turned(hang, 0, -tilt)[2] - hang[2]
        assert 0.0 < tie_move < move < rigid
    # The other way is the mirror image: the right flap swung left is the left flap swung right, mirrored.
    left = settled(side=-side).strands.x
    np.testing.assert_allclose(left[:, :, CLOTH_R], swung[:, :, CLOTH_L] * MIRROR[None, :], rtol=0.0, atol=1e-12)


@cache
def ride(kind: str) -> tuple[float, float, float]:
    """A take with the rules' rider (cloth attributes moving): the flaps' worst stretch and depth, tip travel."""
    times, frames = horse_take(kind)
    rules = RiderModel(params=load_preset("kuhnel2003"), scale=DEFAULT_SCALE)
    src = TakeSource(times, frames, np.asarray(rules.evaluate_batch(frames), dtype=np.float64))
    stepper = FixedStepper(MODEL.step, MODEL.initial(src(0.0)), CONFIG.rate)
    worst_stretch, worst_depth, tips = 0.0, -1.0, []
    while stepper.steps < times[-1] * CONFIG.rate:
        stepper.advance_to(stepper.time + 1.0 / CONFIG.rate, src)
        x = stepper.state.strands.x
        assert np.isfinite(x).all()
        flaps = x[:, :, CLOTH_L:]
        caps = MODEL.anchors(src(stepper.time)).colliders
        worst_stretch = max(worst_stretch, float(stretch(MODEL.strands, x)[:, CLOTH_L:].max()))
        worst_depth = max(worst_depth, float(depth(flaps[2:], caps).max()))
        hips = stepper.state.parents[CLOTH_R]
        tips.append(hips.rotation.T @ (x[-1, :, CLOTH_R] - hips.origin))
    return worst_stretch, worst_depth, float(np.ptp(np.array(tips), axis=0).max())


@pytest.mark.parametrize("kind", ["gallop", "buck", "trot_rear_gallop"])
def test_flaps_keep_their_lengths_stay_outside_and_move_on_takes(kind: str) -> None:
    worst_stretch, worst_depth, travel = ride(kind)
    assert worst_stretch <= 0.05  # the braid's tolerance (tests/physics/test_tail.py)
    assert worst_depth <= 0.0
    assert travel > 0.05  # metres, in the hips frame: the flap flaps


def test_absurd_cloth_attributes_leave_everything_finite() -> None:
    """Finite but absurd attributes hit the tilt limit; NaN ones are held by the stepper, as a bad horse frame is."""
    absurd = settled(up=1e300, side=-1e300)
    assert np.isfinite(absurd.strands.x).all() and np.isfinite(absurd.bones.up).all()
    assert float(stretch(MODEL.strands, absurd.strands.x).max()) <= 0.05
    assert np.isfinite(publish(MODEL, absurd)).all()
    good = drive(up=2.0, side=1.0)

    def flaky(t: float) -> Drive:
        return drive(up=math.nan, side=math.inf) if 0.5 <= t < 0.6 else good

    stepper = FixedStepper(MODEL.step, MODEL.initial(good), CONFIG.rate)
    stepper.advance_to(1.0, flaky)
    assert stepper.bad_inputs == 24  # 0.1 s of 240 Hz steps
    assert np.isfinite(stepper.state.strands.x).all()


def test_flaps_are_published_beside_the_tail_and_braid() -> None:
    names = channel_names(MODEL)
    bones = FLAP.vertices - 1
    for prefix in ("lf_cloth", "rt_cloth"):
        mine = [n for n in names if n.startswith(f"{prefix}_")]
        assert len(mine) == 10 * bones and f"{prefix}_{bones - 1:02d}.qw" in mine and not any(".fan" in n for n in mine)
        assert lookup(f"{prefix}_03.tx").kind is Kind.TRANSLATION and lookup(f"{prefix}_03.rz").kind is Kind.ROTATION
    assert names.index("braid_10.qw") < names.index("lf_cloth_00.tx") < names.index("rt_cloth_00.tx")
    state = settled()
    values = dict(zip(names, publish(MODEL, state), strict=True))
    for prefix, column in (("lf_cloth", CLOTH_L), ("rt_cloth", CLOTH_R)):
        head = [values[f"{prefix}_04.{a}"] for a in ("tx", "ty", "tz")]
        np.testing.assert_allclose(head, state.strands.x[4, :, column], rtol=0.0, atol=1e-15)
    # Bone 00 is relative to the hips frame: at rest with the attributes at zero, the tie's rest rotation.
    local = local_rotations(state)
    right = to_matrix(local[0, CLOTH_R])
    np.testing.assert_allclose(right[:, 0], tie()[:, 1], rtol=0.0, atol=1e-9)
    np.testing.assert_allclose(right, BODY.cloth_rest[1], rtol=0.0, atol=1e-9)
