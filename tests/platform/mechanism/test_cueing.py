"""Motion cueing: one source on floats and compiled, replay, moves that fit, washout, tilt, live changes."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from riderlive.platform.mechanism import cueing as C
from riderlive.platform.mechanism.cueing import CueingModel
from riderlive.platform.mechanism.cueing_params import PRESETS, CueingParams

DT = 1.0 / 120.0
ROOM = ((0.15, 0.15), (0.15, 0.15), (0.15, 0.15), (15.0, 15.0), (18.0, 18.0), (16.0, 16.0))
"""A person-sized platform's single-axis reach (m, deg)."""


def model(**changes: object) -> CueingModel:
    return CueingModel(CueingParams(), ROOM).with_params(**changes)


def run(m: CueingModel, u: np.ndarray, dt: float | np.ndarray = DT) -> np.ndarray:
    return C.run(m, C.initial(m), u, dt)[1]


def take(seconds: float, rate: float = 120.0) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(int(seconds * rate)) / rate
    return t, np.zeros((len(t), 6))


def test_python_source_compiled_step_and_batch_agree() -> None:
    m = model(intensity=80.0)
    t, u = take(8.0)
    rng = np.random.default_rng(1)
    u[:, 1] = 0.03 * np.sin(2 * math.pi * 2.2 * t) + np.where((t > 2) & (t < 3), 0.6, 0.0)
    u[:, 5] = 2.0 * np.sin(2 * math.pi * 2.2 * t) + np.where((t > 2.5) & (t < 4), 30.0, 0.0)
    u[:, 0] = 0.5 * np.clip(t - 5, 0, None) ** 2  # a surge acceleration: tilt coordination
    u[:, 2] = rng.normal(0.0, 0.01, len(t))
    u[100:105, 3] = np.nan
    dt = DT * (1.0 + 0.3 * rng.random(len(t)))
    batch = C.run(m, C.initial(m), u, dt)
    state, steps = C.initial(m), []
    p, s, python = list(m.vector), list(C.initial(m).values), []
    for k in range(len(t)):
        state, y = C.step(m, state, u[k], float(dt[k]))
        steps.append(y)
        out = [0.0] * 6
        C.cue_frame(p, s, u[k].tolist(), float(dt[k]), out)
        python.append(out)
    assert np.array_equal(np.array(steps), batch[1])
    np.testing.assert_allclose(np.array(python), batch[1], rtol=0, atol=1e-12)
    assert np.array_equal(state.values, batch[0].values)
    assert state.counters["nan_frames"] == 5 and state.counters["washout_frames"] > 0


@pytest.mark.parametrize("freq", [1.34, 2.24])
def test_replay_keeps_the_stride_oscillation(freq: float) -> None:
    """The lowest stride-band frequencies of heave and pitch (walk 2 x 0.67 Hz, trot 2 x 1.12 Hz)."""
    m = model()
    t, u = take(20.0)
    u[:, 1] = 0.04 * np.sin(2 * math.pi * freq * t)
    u[:, 5] = 6.0 * np.sin(2 * math.pi * freq * t)
    y = run(m, u)
    late = t > 10
    assert m.scales[1] < 1.0  # scaled so the largest gait fits the room
    assert np.ptp(y[late, 1]) / np.ptp(u[late, 1]) == pytest.approx(m.scales[1], rel=0.01)
    assert np.ptp(y[late, 5]) / np.ptp(u[late, 5]) == pytest.approx(m.scales[5], rel=0.01)
    assert C.run(m, C.initial(m), u, DT)[0].counters["washout_frames"] == 0


def test_drift_and_offsets_are_removed_at_the_replay_cut_off() -> None:
    m = model()
    t, u = take(15.0)
    u[:, 1] = 0.03  # an offset inside the gait envelope, from the second frame
    u[0, 1] = 0.0
    y = run(m, u)
    omega = 2 * math.pi * m.params.drift_cutoff_hz
    expected = m.scales[1] * 0.03 * np.exp(-omega * t[1:])  # the tracker moves before the frame's output
    np.testing.assert_allclose(y[1:, 1], expected, rtol=1e-9)
    # a 2 cm/s drift settles at the first-order lag v / omega
    u[:, 1] = 0.02 * t
    y = run(m, u)
    assert y[-1, 1] == pytest.approx(m.scales[1] * 0.02 / omega, rel=0.01)


def test_a_move_that_fits_is_played_as_it_is_and_comes_back_exactly() -> None:
    m = model(reference_amplitude=(0.02, 0.05, 0.02, 2.5, 2.5, 5.0))  # a platform sized for walk and trot
    assert m.scales[1] == 1.0
    t, u = take(6.0)
    pulse = (t >= 1.0) & (t < 2.5)
    u[pulse, 1] = 0.08  # beyond the gait envelope (1.25 x 0.05 m), below the knee (0.7 x 0.135 m)
    y = run(m, u)
    assert y[pulse, 1].min() >= 0.08 * 0.98
    after = t >= 2.5
    assert np.abs(y[after, 1]).max() <= 0.08 * 0.02  # back at centre, no undershoot to speak of


def test_washout_returns_within_two_seconds_without_passing_centre() -> None:
    m = model()
    t, u = take(8.0)
    jump = (t >= 1.0) & (t < 2.0)
    u[jump, 1] = 0.6 * np.sin(math.pi * (t[jump] - 1.0))  # a 0.6 m rise and fall: four times the room
    y = run(m, u)
    room = m.room[1][1]
    assert y[:, 1].max() <= room + 1e-12
    excursion = np.abs(y[t < 2.0, 1]).max()
    after = t >= 2.0
    sign = np.sign(y[after, 1][0])
    assert (sign * y[after, 1]).min() >= 0.0  # never passes centre once the input is steady
    assert np.all(np.diff(np.abs(y[after, 1])) <= 1e-15)
    assert np.abs(y[t >= 4.0, 1]).max() <= 0.05 * excursion


@settings(max_examples=40, deadline=None)
@given(
    steps=st.lists(st.tuples(st.integers(0, 5), st.floats(-3.0, 3.0), st.floats(0.05, 1.5)), min_size=1, max_size=6),
    preset=st.sampled_from(sorted(PRESETS)),
)
@example(steps=[(0, 2.0, 1.0), (0, 1.0, 1.0), (1, 1.0, 0.5)], preset="gentle")  # washout released within the 2 s
def test_any_input_ending_steady_returns_monotonically(steps: list[tuple[int, float, float]], preset: str) -> None:
    """Whatever came before, once the saddle holds still every axis' cue shrinks toward centre and never
    crosses it; when washout was engaged and stays so it is within 5 % of its excursion 2 s later, and
    when washout releases in those 2 s (the cue back in its gait envelope for ``washout_hold_s``) it is
    inside the envelope. (Tilt off: its filter settles with a sign change of the acceleration, by design.)"""
    m = CueingModel(PRESETS[preset], ROOM).with_params(tilt_gain=0.0)
    pieces, last = [], np.zeros(6)
    scale = np.array([0.1, 0.1, 0.1, 10.0, 10.0, 10.0])
    for axis, level, seconds in steps:
        last = last.copy()
        last[axis] = level * scale[axis]
        pieces.append(np.tile(last, (int(seconds * 120), 1)))
    held = np.tile(last, (600, 1))
    u = np.vstack([np.zeros((1, 6)), *pieces, held])
    state, y = C.run(m, C.initial(m), u, DT)
    start = len(u) - len(held) - 1
    tail = y[start:]
    for axis in range(6):
        sign = np.sign(tail[0, axis])
        assert (sign * tail[:, axis]).min() >= -1e-15
        assert np.all(np.diff(np.abs(tail[:, axis])) <= 1e-15)
        room = max(m.room[axis])
        assert np.abs(y[:, axis]).max() <= room + 1e-12
    if state.counters["washout_frames"] and np.abs(tail[0]).max() > 0:
        engaged_at_end = C.run(m, C.initial(m), u[: start + 1], DT)[0].washout > 0.5
        if engaged_at_end and C.run(m, C.initial(m), u[: start + 241], DT)[0].washout > 0.5:
            # engaged throughout: 2 s of washout rate bring every axis within 5 %
            assert np.all(np.abs(tail[240]) <= 0.05 * np.abs(y[: start + 1]).max(axis=0) + 1e-12)
        elif engaged_at_end:
            # released within the 2 s, as documented: every axis' cue had been back inside its gait
            # envelope for washout_hold_s, and replay's slow drift removal takes the rest from there
            gate = m.vector[C.GATE : C.GATE + 6]
            assert np.all(np.abs(tail[240]) <= gate + 1e-12)


def test_tilt_coordination_renders_a_sustained_acceleration() -> None:
    m = model(tilt_max_deg=15.0)
    t, u = take(12.0)
    u[:, 0] = 0.5 * 2.0 * t**2  # 2 m/s^2 forward
    u[:, 2] = -0.5 * 1.0 * t**2  # 1 m/s^2 to the left
    state = C.initial(m)
    tilts = []
    for k in range(len(t)):
        state, _ = C.step(m, state, u[k], DT)
        tilts.append(state.tilt)
    pitch, roll = np.array(tilts).T
    assert pitch[-1] == pytest.approx(math.degrees(math.atan(2.0 / 9.80665)), abs=0.05)  # nose up
    assert roll[-1] == pytest.approx(math.degrees(math.atan(1.0 / 9.80665)), abs=0.05)  # rolled right
    rate = m.params.tilt_rate_dps * DT
    assert np.abs(np.diff(pitch)).max() <= rate + 1e-12
    assert np.abs(np.diff(roll)).max() <= rate + 1e-12
    capped = C.run(model(tilt_max_deg=5.0), C.initial(m), u, DT)[0]
    assert capped.tilt[0] == pytest.approx(5.0)


def test_intensity_zero_holds_home_and_changes_blend() -> None:
    t, u = take(12.0)
    u[:, 1] = 0.03 * np.sin(2 * math.pi * 2.0 * t)
    u[:, 5] = 3.0 * np.sin(2 * math.pi * 2.0 * t)
    assert np.abs(run(model(intensity=0.0), u)).max() == 0.0
    full = model()
    low = full.with_params(intensity=20.0)
    state, ys = C.initial(full), []
    for k in range(len(t)):
        state, y = C.step(full if t[k] < 3.0 else low, state, u[k], DT)
        ys.append(y)
    y = np.array(ys)
    steady_step = np.abs(np.diff(y[(t > 1) & (t < 3), 5])).max()
    assert np.abs(np.diff(y[:, 5])).max() <= steady_step * 1.05  # no jump when the intensity drops
    late = t > 3.0 + 10 * full.params.blend_s
    assert np.ptp(y[late, 5]) / np.ptp(u[late, 5]) == pytest.approx(0.2 * full.scales[5], rel=0.01)
    assert state.params is low.vector  # the blend has finished


def test_non_finite_input_holds_the_last_value() -> None:
    m = model()
    _t, u = take(2.0)
    u[:, 1] = 0.02
    u[50:60] = np.nan
    u[70, 3] = np.inf
    state, y = C.run(m, C.initial(m), u, DT)
    assert np.all(np.isfinite(y))
    assert state.counters["nan_frames"] == 11
    np.testing.assert_allclose(y[50:60, 1], y[49, 1] * np.exp(-2 * math.pi * 0.08 * DT * np.arange(1, 11)), rtol=1e-9)


def test_axes_a_mechanism_lacks_get_no_cue() -> None:
    axes = (False, True, False, True, False, True)
    m = CueingModel(CueingParams(), ROOM, axes)
    t, u = take(3.0)
    u[:] = np.sin(2 * math.pi * 1.5 * t)[:, None] * np.array([0.05, 0.03, 0.05, 2.0, 3.0, 2.0])
    y = run(m, u)
    assert np.abs(y[:, [0, 2, 4]]).max() == 0.0
    assert np.abs(y[:, [1, 3, 5]]).max() > 0.0
    assert m.scales[0] == 0.0 and m.scales[1] > 0.0


def test_automatic_scale_fits_the_reference_gait_below_the_knee() -> None:
    small = CueingModel(CueingParams(), ((0.05, 0.05), (0.04, 0.06), (0.05, 0.05), (10, 10), (12, 12), (10, 12)))
    p = small.params
    ref = p.reference_amplitude
    assert small.scales[1] == pytest.approx(p.knee * p.share * 0.04 / ref[1])
    assert small.scales[5] == pytest.approx(p.knee * p.share * 10.0 / ref[5])
    assert CueingModel(p, ((1.0, 1.0),) * 3 + ((90.0, 90.0),) * 3).scales == (1.0,) * 6  # never above 1
    assert small.with_params(scale=(1, 0.5, 1, 1, 1, 1)).scales[1] == 0.5


def test_presets() -> None:
    assert set(PRESETS) == {"gentle", "standard", "lively"}
    gentle, lively = PRESETS["gentle"], PRESETS["lively"]
    assert gentle.washout_translation_hz < lively.washout_translation_hz
    assert gentle.tilt_rate_dps < lively.tilt_rate_dps
    assert model().with_preset("gentle", intensity=50.0).params.intensity == 50.0
    with pytest.raises(ValueError, match="unknown cueing preset"):
        model().with_preset("wild")
