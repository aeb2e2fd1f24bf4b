"""Inverse kinematics: hand-computed poses, forward kinematics round trips, floats == arrays, the scale-back."""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from riderlive.platform.mechanism.config import build_geometry, load_platform
from riderlive.platform.mechanism.geometry import Geometry, Kind, hexagon, rotation, tangential_arms
from riderlive.platform.mechanism.ik import ARRAY, SCALAR, Workspace, axis_ranges, forward, make_ik, make_margin

PLATFORMS = ("stewart_linear", "stewart_rotary", "heave_pitch_roll")


@cache
def geometry(name: str) -> Geometry:
    return build_geometry(load_platform(name))


@cache
def ranges(name: str) -> tuple[tuple[float, float], ...]:
    return axis_ranges(geometry(name))


def random_poses(name: str, n: int, spread: float, seed: int) -> np.ndarray:
    """``n`` poses around home, each axis uniform within ``spread`` x its single-axis reach."""
    g, r = geometry(name), ranges(name)
    span = np.array([max(d, u) for d, u in r]) * spread
    return np.asarray(g.home) + np.random.default_rng(seed).uniform(-1.0, 1.0, size=(n, 6)) * span


def lengths(name: str, pose: tuple[float, ...]) -> list[float]:
    g = geometry(name)
    return [q + g.min_length for q in make_ik(g, SCALAR)(*pose)[0]]


# ------------------------------------------------------------------ hand-computed poses


def test_rotation_signs_follow_the_rig_frame() -> None:
    nose = np.array([1.0, 0.0, 0.0])
    right = np.array([0.0, 0.0, 1.0])
    assert (np.array(rotation(0, 0, 10)) @ nose)[1] == pytest.approx(math.sin(math.radians(10)))  # +rz: nose up
    assert (np.array(rotation(10, 0, 0)) @ right)[1] == pytest.approx(-math.sin(math.radians(10)))  # +rx: right down
    assert (np.array(rotation(0, 10, 0)) @ nose)[2] == pytest.approx(-math.sin(math.radians(10)))  # +ry: turns left
    a, b, g = (math.radians(v) for v in (7.0, -11.0, 23.0))
    rx = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]])
    rz = np.array([[math.cos(g), -math.sin(g), 0], [math.sin(g), math.cos(g), 0], [0, 0, 1]])
    np.testing.assert_allclose(np.array(rotation(7.0, -11.0, 23.0)), ry @ rz @ rx, atol=1e-15)


def test_linear_hexagon_lengths_by_the_law_of_cosines() -> None:
    # config: base radius 0.8, platform radius 0.5, spreads 20 deg: base and platform joints of a leg
    # are 40 deg apart around the vertical; home origin 0.48 m up; cue centre 0.45 m above the origin.
    rb, rp, h, lmin = 0.8, 0.5, 0.48, 0.60
    horizontal = rb * rb + rp * rp - 2 * rb * rp * math.cos(math.radians(40.0))
    home = geometry("stewart_linear").home
    assert home == pytest.approx((0.0, 0.93, 0.0, 0.0, 0.0, 0.0))
    assert lengths("stewart_linear", home) == pytest.approx([math.sqrt(horizontal + h * h)] * 6, abs=1e-12)
    heave = (0.0, 0.93 + 0.07, 0.0, 0.0, 0.0, 0.0)
    assert lengths("stewart_linear", heave) == pytest.approx([math.sqrt(horizontal + 0.55**2)] * 6, abs=1e-12)
    # yaw about the vertical through the centre: platform joints turn by -psi around the circle
    psi = 12.0
    yawed = lengths("stewart_linear", (0.0, 0.93, 0.0, 0.0, psi, 0.0))
    for i, length in enumerate(yawed):
        delta = -40.0 if i % 2 == 0 else 40.0
        d2 = rb * rb + rp * rp - 2 * rb * rp * math.cos(math.radians(delta - psi))
        assert length == pytest.approx(math.sqrt(d2 + h * h), abs=1e-12)
    q, reach = make_ik(geometry("stewart_linear"), SCALAR)(*home)
    assert reach == 1.0 and q[0] == pytest.approx(math.sqrt(horizontal + h * h) - lmin, abs=1e-12)


def test_heave_pitch_roll_lengths_by_hand() -> None:
    h = 0.50
    theta, phi = math.radians(6.0), math.radians(-4.0)
    pitched = lengths("heave_pitch_roll", (0.0, h, 0.0, 0.0, 0.0, 6.0))
    front = math.hypot(0.55 * math.cos(theta) - 0.55, h + 0.55 * math.sin(theta))
    rear = math.hypot(0.35 - 0.35 * math.cos(theta), h - 0.35 * math.sin(theta))
    assert pitched == pytest.approx([front, rear, rear], abs=1e-12)
    rolled = lengths("heave_pitch_roll", (0.0, h, 0.0, -4.0, 0.0, 0.0))
    left = math.hypot(0.45 - 0.45 * math.cos(phi), h + 0.45 * math.sin(phi))  # z = -0.45 rises when rolling left
    right = math.hypot(0.45 - 0.45 * math.cos(phi), h - 0.45 * math.sin(phi))
    assert rolled == pytest.approx([h, left, right], abs=1e-12)
    # the centre guide holds surge, sway and yaw: they change nothing
    assert lengths("heave_pitch_roll", (0.3, h, -0.2, 0.0, 25.0, 0.0)) == pytest.approx([h] * 3, abs=1e-15)


def _rotary(a: float = 0.06, s: float = 0.25) -> tuple[Geometry, list[tuple[float, ...]]]:
    base, platform = hexagon(0.25, 20.0, 0.18, 20.0)
    arms = tangential_arms(base)
    g = Geometry(
        kind=Kind.STEWART_ROTARY,
        base=base,
        platform=platform,
        lower=(-60.0,) * 6,
        upper=(60.0,) * 6,
        hard_lower=(-62.0,) * 6,
        hard_upper=(62.0,) * 6,
        max_speed=(400.0,) * 6,
        max_accel=(8000.0,) * 6,
        home=(0.0, 0.2, 0.0, 0.0, 0.0, 0.0),
        park=(0.0, 0.2, 0.0, 0.0, 0.0, 0.0),
        arm=a,
        rod=s,
        arm_direction=arms,
    )
    return g, [(b[0], b[2], p[0], p[2], d[0], d[1]) for b, p, d in zip(base, platform, arms, strict=True)]


@pytest.mark.parametrize("alpha", [0.0, 30.0, -45.0])
def test_rotary_crank_angle_by_hand(alpha: float) -> None:
    """With the crank at alpha its tip is at b + a (cos(alpha) d + sin(alpha) up); the platform height
    that puts every rod (length s) on its tip follows by Pythagoras, and IK must return alpha."""
    a, s = 0.06, 0.25
    g, legs = _rotary(a, s)
    c, sn = math.cos(math.radians(alpha)), math.sin(math.radians(alpha))
    heights = []
    for bx, bz, px, pz, dx, dz in legs:
        tip_x, tip_z = bx + a * c * dx, bz + a * c * dz
        heights.append(a * sn + math.sqrt(s * s - (px - tip_x) ** 2 - (pz - tip_z) ** 2))
    assert max(heights) - min(heights) < 1e-12  # the layout is symmetric
    q, reach = make_ik(g, SCALAR)(0.0, heights[0], 0.0, 0.0, 0.0, 0.0)
    assert reach >= 0.0
    assert q == pytest.approx([alpha] * 6, abs=1e-9)


def test_rotary_out_of_reach_is_flagged() -> None:
    g, _ = _rotary()
    _, reach = make_ik(g, SCALAR)(0.0, 0.40, 0.0, 0.0, 0.0, 0.0)  # rod + arm < 0.40 m: no crank angle works
    assert reach < 0.0
    _, margin = make_margin(g, SCALAR)(0.0, 0.40, 0.0, 0.0, 0.0, 0.0)
    assert margin < 0.0


# ------------------------------------------------------------------ round trips and the two forms


def _poses(name: str, share: float) -> st.SearchStrategy[tuple[float, ...]]:
    g, r = geometry(name), ranges(name)
    axes = [
        st.floats(-share * down, share * up) if free else st.just(0.0)
        for (down, up), free in zip(r, g.kind.axes, strict=True)
    ]
    return st.tuples(*axes).map(lambda d: tuple(h + v for h, v in zip(g.home, d, strict=True)))


@pytest.mark.parametrize("name", PLATFORMS)
@settings(max_examples=15, deadline=None)
@given(data=st.data())
def test_forward_kinematics_round_trip(name: str, data: st.DataObject) -> None:
    """Any pose inside the workspace: IK, then numerical FK from home, gives the pose back."""
    g = geometry(name)
    pose = data.draw(_poses(name, 0.6))
    q, margin = make_margin(g, SCALAR)(*pose)
    assume(margin >= 0.0)
    back = forward(g, q)
    assert np.max(np.abs(np.subtract(back, pose))) <= 1e-9


@pytest.mark.parametrize("name", PLATFORMS)
def test_scalar_and_array_ik_agree(name: str) -> None:
    g = geometry(name)
    poses = random_poses(name, 500, 1.5, seed=3)
    q_arr, reach_arr = make_ik(g, ARRAY)(*poses.T)
    for k in range(0, 500, 7):
        q, reach = make_ik(g, SCALAR)(*poses[k])
        assert np.asarray(q) == pytest.approx(np.asarray(q_arr)[:, k], abs=1e-12)
        assert reach == pytest.approx(np.broadcast_to(reach_arr, (500,))[k], abs=1e-12)


# ------------------------------------------------------------------ workspace and scale-back


@pytest.mark.parametrize("name", PLATFORMS)
@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_any_pose_is_fitted_inside_the_soft_limits(name: str, data: st.DataObject) -> None:
    g = geometry(name)
    ws = Workspace(g)
    pose = data.draw(_poses(name, 4.0))
    q, lam = ws.fit(pose)  # type: ignore[arg-type]
    assert 0.0 <= lam <= 1.0
    assert all(lo - 1e-12 <= v <= hi + 1e-12 for v, lo, hi in zip(q, g.lower, g.upper, strict=True))
    margin = make_margin(g, SCALAR)
    _, m_target = margin(*pose)
    if m_target >= 0.0:
        assert lam == 1.0
    else:  # scaled back along the line from home, to (just inside) the boundary
        kept = tuple(h + lam * (p - h) for h, p in zip(g.home, pose, strict=True))
        q_kept, m_kept = margin(*kept)
        assert q_kept == pytest.approx(q, abs=1e-12)
        assert 0.0 <= m_kept < 0.02  # within 2 % of a range of the boundary (ik.SHRINK_STEPS)
        beyond = tuple(h + min(1.0, lam + 1e-3) * (p - h) for h, p in zip(g.home, pose, strict=True))
        assert margin(*beyond)[1] < m_kept + 1e-9


@pytest.mark.parametrize("name", PLATFORMS)
def test_batch_fit_equals_scalar_fit(name: str) -> None:
    g = geometry(name)
    poses = random_poses(name, 400, 2.0, seed=11)
    ws = Workspace(g)
    q_batch, lam_batch = ws.fit_batch(poses)
    assert (lam_batch < 1.0).sum() > 50  # the test covers the scale-back
    for k in range(0, 400, 3):
        q, lam = ws.fit(tuple(poses[k]))  # type: ignore[arg-type]
        # A pose scaled back is searched to the boundary, where the margin is flat and a rotary
        # arm at full reach ill-conditioned: an ulp of difference in a primitive (NumPy's
        # AVX-512 exp/atan2/tan against libm's, docs/testing.md) moved one scale 6e-11 and its
        # angles 1e-8 rad (2026-11-28, AVX-512 host). Within the workspace: 1e-12.
        assert lam == pytest.approx(lam_batch[k], abs=1e-12 if lam_batch[k] == 1.0 else 1e-9)
        assert np.asarray(q) == pytest.approx(q_batch[k], abs=1e-12 if lam_batch[k] == 1.0 else 1e-6)


def test_scale_back_is_continuous_along_a_path() -> None:
    """A target sweeping out of the workspace and back: the kept pose moves in small steps, never jumps."""
    g = geometry("stewart_linear")
    ws = Workspace(g)
    t = np.linspace(0.0, 1.0, 2001)
    heave = 0.5 * np.sin(math.pi * t)  # up to 0.5 m: far outside
    pitch = 30.0 * np.sin(math.pi * t)
    previous = None
    for dy, dp in zip(heave, pitch, strict=True):
        q, _ = ws.fit((0.0, g.home[1] + dy, 0.0, 0.0, 0.0, dp))
        if previous is not None:
            assert np.max(np.abs(np.subtract(q, previous))) < 2e-3  # a 1/2000 step of the sweep
        previous = q


@pytest.mark.parametrize("name", PLATFORMS)
def test_axis_ranges_end_on_the_boundary(name: str) -> None:
    g = geometry(name)
    margin = make_margin(g, SCALAR)
    for axis, ((down, up), free) in enumerate(zip(ranges(name), g.kind.axes, strict=True)):
        if not free:
            assert (down, up) == (0.0, 0.0)
            continue
        for sign, reach in ((-1.0, down), (1.0, up)):
            pose = list(g.home)
            pose[axis] += sign * reach
            assert 0.0 <= margin(*pose)[1] < 1e-7
            pose[axis] += sign * 1e-6
            assert margin(*pose)[1] < 0.0


def test_a_line_that_leaves_and_enters_the_workspace_again_is_scaled_back_to_its_first_exit() -> None:
    """Two neighbouring poses far outside (hypothesis found them, 2026-11-28): along the line
    from home the margin goes out at ~0.25 and in again at ~0.65. The scale-back keeps the
    first exit for both (before: 0.70 and 0.13, a jump of the target between two frames), and
    the whole way from home to the kept pose is inside."""
    g = geometry("stewart_linear")
    ws, margin = Workspace(g), make_margin(g, SCALAR)
    poses = [
        (0.0, 0.5667187499999999, 0.0390625, -0.5, 1.0, 51.0),
        (0.0, 0.5628124999999999, 0.0390625, -0.5, 0.0, 52.0),
    ]
    lams = []
    for pose in poses:
        _, lam = ws.fit(pose)
        lams.append(lam)
        way = [tuple(h + s * (p - h) for h, p in zip(g.home, pose, strict=True)) for s in np.linspace(0, lam, 50)]
        along = [margin(*kept)[1] for kept in way]
        assert min(along) >= 0.0, (pose, lam)
        assert 0.2 < lam < 0.3, (pose, lam)
    assert abs(lams[0] - lams[1]) < 0.01, lams
    _, lam_batch = ws.fit_batch(np.array(poses))
    assert lam_batch.tolist() == pytest.approx(lams, abs=1e-12)
