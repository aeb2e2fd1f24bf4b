"""Saddle to actuators over every shot and platform: limits, return to centre, the trot's energy, tick == bake."""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest

from riderlive.platform import PlatformModel, bake, initial, shipped_platforms
from riderlive.platform.mechanism import limits, pipeline
from riderlive.platform.mechanism.ik import forward
from riderlive.platform.mechanism.pipeline import Bake

from ..takes import RATE, SHOTS, gait, shot

PLATFORMS = tuple(shipped_platforms())
DT = 1.0 / RATE
RETURN_S = 2.0
PASS_SHARE = 0.05


@cache
def platform(name: str) -> PlatformModel:
    return PlatformModel.load(name)


@cache
def baked(name: str, shot_name: str) -> Bake:
    return bake(platform(name), shot(shot_name).saddle, DT)


def achieved(model: PlatformModel, positions: np.ndarray) -> np.ndarray:
    """The pose the actuators really put the platform in (forward kinematics), relative to home."""
    poses, guess = [], None
    for q in positions:
        guess = forward(model.geometry, tuple(q), guess)
        poses.append(guess)
    return np.asarray(poses) - np.asarray(model.geometry.home)


@pytest.mark.parametrize("name", PLATFORMS)
@pytest.mark.parametrize("shot_name", SHOTS)
def test_no_command_outside_the_limits_and_no_step_over_them(name: str, shot_name: str) -> None:
    model, result = platform(name), baked(name, shot_name)
    g = model.geometry
    q = result.positions
    assert np.all(q >= np.asarray(g.lower) - 1e-12) and np.all(q <= np.asarray(g.upper) + 1e-12)
    v = np.diff(np.vstack([model.home_positions, q]), axis=0) / DT
    assert np.all(np.abs(v) <= np.asarray(g.max_speed) * (1 + 1e-9))
    a = np.diff(np.vstack([np.zeros(g.legs), v]), axis=0) / DT
    assert np.all(np.abs(a) <= np.asarray(g.max_accel) * (1 + 1e-9) + 1e-9)
    assert np.all(result.scale > 0.0) and np.all(result.scale <= 1.0)


def moved_axes(take_name: str) -> list[int]:
    """Axes the shot's move drives well beyond the gait before it (the others only carry the gait)."""
    take = shot(take_name)
    assert take.move is not None and take.before is not None
    t, u = take.t, take.saddle
    before = (t >= take.before[0] + 0.5) & (t < take.before[1])
    during = (t >= take.move[0]) & (t < take.move[1])
    centre = u[before].mean(axis=0)
    swing = np.abs(u[before] - centre).max(axis=0)
    excursion = np.abs(u[during] - centre).max(axis=0)
    return [axis for axis in range(6) if excursion[axis] > 2.0 * swing[axis] + 1e-9]


@pytest.mark.parametrize("name", PLATFORMS)
@pytest.mark.parametrize("shot_name", [s for s in SHOTS if shot(s).move is not None])
def test_return_to_centre_after_a_move(name: str, shot_name: str) -> None:
    """Within 2 s of the move's end the platform's pose is back at centre (the stride's average, when a
    gait follows) within 5 % of the move's excursion, and never passes centre by more than 5 % of it.

    The pose is the one the platform is commanded to (cueing and the scale-back, what washout
    decides); where a following canter is faster than the actuators, the safety stage distorts the
    oscillation itself, which is the trot energy test's business, not the return's."""
    model, result, take = platform(name), baked(name, shot_name), shot(shot_name)
    assert take.move is not None
    t = take.t
    start, end = take.move
    during = (t >= start) & (t < end)
    every = 1
    window = slice(int(end * RATE), int((end + RETURN_S + 1.0) * RATE), every)
    commanded = result.pose - np.asarray(model.geometry.home)
    after = commanded[window]
    t_after = t[window]
    axes = [a for a in moved_axes(shot_name) if model.geometry.kind.axes[a]]
    assert axes, "the move drives some axis of the platform"
    for axis in axes:
        excursion = np.abs(commanded[during, axis]).max()
        x = after[:, axis]
        if take.after_stride_hz:  # average over one stride: what is left is the washout's residual
            n = max(round(RATE / every / take.after_stride_hz), 1)
            x = np.convolve(x, np.ones(n) / n, mode="valid")
            t_x = t_after[n // 2 : n // 2 + len(x)]
        else:
            t_x = t_after
        side = np.sign(x[0]) or 1.0
        assert (side * x).min() >= -PASS_SHARE * excursion, f"axis {axis} passes centre"
        late = t_x >= end + RETURN_S
        assert np.abs(x[late]).max() <= PASS_SHARE * excursion, f"axis {axis} is not back within {RETURN_S} s"


@cache
def trot_energy(name: str) -> dict[str, tuple[float, float, float]]:
    """Per axis (heave, pitch): the platform's oscillation energy in the stride band (0.5-3.5 x the
    stride frequency) as a share of the saddle's, raw and relative to the cue's scale, and the scale."""
    model = platform(name)
    u, stride = gait("trot", 10.0)
    result = bake(model, u, DT)
    every = 4
    rate = RATE / every
    first = int(2.0 * RATE)  # after the start-up
    strides = math.floor((len(u) - first) / RATE * stride)
    last = first + round(strides / stride * RATE)
    pose = achieved(model, result.positions[first:last:every])
    saddle = u[first:last:every]
    f = np.fft.rfftfreq(len(saddle), 1.0 / rate)
    band = (f >= 0.5 * stride) & (f <= 3.5 * stride)

    def energy(x: np.ndarray) -> float:
        return float((np.abs(np.fft.rfft(x - x.mean()))[band] ** 2).sum())

    out = {}
    for axis, label in ((1, "ty"), (5, "rz")):
        raw = energy(pose[:, axis]) / energy(saddle[:, axis])
        k = model.cueing.scales[axis] * model.cueing.params.intensity / 100.0
        out[label] = (raw, raw / (k * k), k)
    return out


@pytest.mark.parametrize("name", PLATFORMS)
def test_the_trot_keeps_its_vertical_and_pitch_energy(name: str) -> None:
    """>= 80 % of the saddle's heave and pitch energy in the stride band, of what the workspace allows:
    where the platform's room needs a cue scale below 1, the target is 80 % of the scaled cue's energy."""
    for label, (raw, relative, scale) in trot_energy(name).items():
        print(f"{name} trot {label}: {raw:.0%} of the saddle's energy (scale {scale:.2f}, {relative:.0%} of the cue)")
        assert relative >= 0.8, label
        if scale == 1.0:
            assert raw >= 0.8, label


@pytest.mark.parametrize("name", PLATFORMS)
def test_the_tick_equals_the_bake(name: str) -> None:
    model = platform(name)
    take = shot("buck")
    result = baked(name, "buck")
    state = initial(model)
    for k in range(len(take.t)):
        state, frame = pipeline.step(model, state, take.saddle[k], DT)
        assert np.max(np.abs(frame.positions - result.positions[k])) <= 1e-9
        assert frame.aim.scale == pytest.approx(result.scale[k], abs=1e-12)
    assert state.counters == result.state.counters


def test_a_saddle_stream_with_holes_moves_nothing_unasked() -> None:
    model = platform("stewart_linear")
    u = shot("jump").saddle.copy()
    u[300:330, :] = np.nan  # a dropout
    u[400, 1] = np.inf
    result = bake(model, u, DT)
    assert result.state.counters["nan_frames"] == 31
    assert np.all(np.isfinite(result.positions))
    # through the hole the cue holds the last pose and decays toward centre, never jumps
    hole = result.positions[299:331]
    assert np.abs(np.diff(hole, axis=0)).max() <= np.max(model.geometry.max_speed) * DT


def test_soft_start_from_park_then_run_within_the_limits() -> None:
    """What the lifecycle does on arm: from the parked positions, ease over soft_start_s toward the live
    targets, through the safety stage; the commands join the running targets and never break a limit."""
    model = platform("stewart_rotary")
    u, _ = gait("trot", 5.0)
    present = model.park_positions
    cue_state = initial(model).cueing
    safety = limits.SafetyState.at(present)
    commands, targets = [], []
    for k in range(len(u)):
        cue_state, aim = pipeline.aim(model, cue_state, u[k], DT)
        elapsed = k * DT
        soft = elapsed < model.soft_start_s
        goal = limits.eased(present, aim.targets, elapsed, model.soft_start_s) if soft else aim.targets
        safety, q = limits.step(model.safety, safety, goal, DT)
        commands.append(q)
        targets.append(aim.targets)
    q = np.array(commands)
    g = model.geometry
    v = np.diff(np.vstack([present, q]), axis=0) / DT
    assert np.all(np.abs(v) <= np.asarray(g.max_speed) * (1 + 1e-9))
    assert np.all(q >= np.asarray(g.lower) - 1e-12) and np.all(q <= np.asarray(g.upper) + 1e-12)
    joined = int((model.soft_start_s + 0.5) * RATE)
    assert np.abs(q[joined : joined + 60] - np.array(targets)[joined : joined + 60]).max() < 1e-6
