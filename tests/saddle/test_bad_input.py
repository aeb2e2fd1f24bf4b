"""Bad saddle input: each case a counted, documented fallback, and never a rider that flails.

NaN or a missing axis, a jump of metres (a glitch, or a re-zero that stays), a
constant stream, white noise, a 1 Hz stream, a stream that stops, samples out of
order; and hypothesis-made garbage, after which every rebuilt frame is finite and
bounded.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.channels import HORSE, HORSE_INDEX, Kind
from riderlive.horse.script import gait_script
from riderlive.saddle.estimate import estimate
from riderlive.saddle.estimator import Lock, Model, State, step
from riderlive.saddle.rebuild import horse_frame, rebuild
from riderlive.saddle.synthetic import IMU_STRAP, record
from riderlive.saddle.trial import RIDER

MODEL = Model()
ZERO = [0.0] * len(HORSE)


@pytest.fixture(scope="module")
def trot() -> tuple[np.ndarray, np.ndarray]:
    rec = record(gait_script("trot", 6.0, seed=2), 120.0, start=0.3, seed=2)
    assert rec.saddle.t is not None
    return rec.saddle.t, rec.saddle.values


@pytest.fixture(scope="module")
def clean(trot):
    return rebuild(MODEL, *trot)


def _run(times: np.ndarray, values: np.ndarray):
    return rebuild(MODEL, times, values)


ROTATION = np.array([c.kind is Kind.ROTATION for c in HORSE])


def _close(a: np.ndarray, b: np.ndarray, metres: float, degrees: float) -> None:
    """Frames alike within ``metres`` on lengths and ``degrees`` on angles (one held sample moves both)."""
    np.testing.assert_allclose(a[:, ~ROTATION], b[:, ~ROTATION], atol=metres)
    np.testing.assert_allclose(a[:, ROTATION], b[:, ROTATION], atol=degrees)


def test_a_missing_axis_now_and_then_is_counted_and_the_lock_holds(trot, clean) -> None:
    t, v = trot
    spoiled = v.copy()
    spoiled[::7, 3] = np.nan  # roll lost on every 7th frame
    spoiled[::11, 1] = np.inf
    run = _run(t, spoiled)
    counters = estimate(run.final).counters
    assert counters["missing"] == len(range(0, len(t), 7)) + len(range(0, len(t), 11)) - len(range(0, len(t), 77))
    assert counters["losses"] == 0 and run.final.lock is Lock.LOCKED
    np.testing.assert_allclose(run.horse[t > 3.0][:, :12], clean.horse[t > 3.0][:, :12], atol=0.01)


def test_without_the_sideways_axes_the_diagonal_is_kept_not_tossed(trot) -> None:
    t, v = trot
    spoiled = v.copy()
    spoiled[:, [2, 3, 4]] = np.nan  # no side, roll or yaw: the trot's two diagonals look alike
    run = _run(t, spoiled)
    assert run.final.lock is Lock.LOCKED and run.final.tracking.fit is not None and run.final.tracking.fit.half
    assert estimate(run.final).counters["locks"] == 1  # one choice, kept


def test_a_glitch_of_metres_is_dropped(trot, clean) -> None:
    t, v = trot
    spoiled = v.copy()
    spoiled[500, 1] += 3.0
    spoiled[600, 3] += 90.0
    run = _run(t, spoiled)
    counters = estimate(run.final).counters
    assert counters["glitches"] == 2 and counters["rebases"] == 0 and counters["losses"] == 0
    _close(run.horse, clean.horse, 0.02, 1.0)


def test_a_jump_that_stays_is_a_re_zero_absorbed_without_a_jump_out(trot, clean) -> None:
    t, v = trot
    spoiled = v.copy()
    spoiled[500:, 0] += 2.0  # the sensor re-zeroed: forward 2 m from here on
    spoiled[500:, 4] += 40.0
    run = _run(t, spoiled)
    counters = estimate(run.final).counters
    assert counters["rebases"] == 1 and counters["glitches"] == 0 and counters["losses"] == 0
    _close(run.horse, clean.horse, 0.02, 1.0)  # nothing jumps out


def test_a_constant_stream_is_a_standing_horse(trot) -> None:
    t, _ = trot
    run = _run(t, np.tile([0.1, -0.2, 0.3, 1.0, 2.0, -3.0], (len(t), 1)))
    assert run.final.lock is Lock.STILL and estimate(run.final).gait == "halt"
    np.testing.assert_allclose(run.horse, 0.0, atol=1e-9)


@pytest.mark.parametrize("scale", [1.0, 50.0])
def test_white_noise_never_locks_and_the_rider_sits_still(trot, scale: float) -> None:
    t, v = trot
    noise = np.random.default_rng(7).normal(size=v.shape) * np.array([0.02, 0.02, 0.02, 2.0, 2.0, 2.0]) * scale
    run = _run(t, noise)
    assert "locked" not in run.lock
    assert np.all(run.horse == 0.0)
    neutral = RIDER.evaluate(ZERO)
    np.testing.assert_allclose(RIDER.evaluate_batch(run.horse), np.tile(neutral, (len(t), 1)), atol=1e-12)


def test_a_1_hz_stream_has_no_signal_and_the_rider_sits_still() -> None:
    rec = record(gait_script("trot", 20.0), 10.0)
    assert rec.saddle.t is not None
    run = _run(rec.saddle.t[::10], rec.saddle.values[::10])
    assert set(run.lock) == {"no_signal"}
    assert estimate(run.final).counters["gaps"] == len(run.lock) - 1
    assert np.all(run.horse == 0.0)


def test_a_stream_that_stops_runs_on_for_the_hold_then_eases_to_standing(trot, clean) -> None:
    t, _ = trot
    run = clean
    last = float(t[-1])
    on = horse_frame(MODEL, run.final, last + 0.5 * MODEL.hold)
    assert max(abs(x) for x in on[:12]) > 0.05  # still trotting
    easing = [horse_frame(MODEL, run.final, last + MODEL.hold + k * 0.05) for k in range(12)]
    heights = [max(abs(f[HORSE_INDEX["lfHoof.ty"]]), abs(f[HORSE_INDEX["rbHoof.ty"]])) for f in easing]
    assert heights[-1] == 0.0
    settled = horse_frame(MODEL, run.final, last + MODEL.hold + MODEL.ease + 1e-9)
    later = horse_frame(MODEL, run.final, last + 60.0)
    root = HORSE_INDEX["root.tx"]
    assert settled[:root] == ZERO[:root] and later[:root] == ZERO[:root]
    assert settled[root] == later[root] > 0.0  # the distance stops growing, smoothly (coasting to a stop)


def test_samples_out_of_order_or_misshapen_are_counted_and_ignored(trot) -> None:
    t, v = trot
    state = State()
    for ti, row in zip(t[:300], v[:300].tolist(), strict=True):
        state = step(MODEL, state, ti, row)
    before = state
    for bad_t, bad_row in [
        (t[299], v[300].tolist()),  # same time again
        (t[100], v[300].tolist()),  # back in time
        (math.nan, v[300].tolist()),
        (t[300], [math.nan] * 6),  # nothing usable
        (t[300], [1e9, -1e9, 1e12, 5e3, -9e3, 1e300]),  # nothing plausible
        (t[300], [*v[300].tolist(), 0.0]),  # seven values
        (t[300], v[300].tolist()[:5]),
    ]:
        state = step(MODEL, state, bad_t, bad_row)
    assert estimate(state).counters["empty"] == 7
    assert state.samples == before.samples + 7
    assert state._replace(samples=0, tracking=None) == before._replace(samples=0, tracking=None)


def test_step_is_pure(trot) -> None:
    t, v = trot
    state = State()
    for ti, row in zip(t[:400], v[:400].tolist(), strict=True):
        state = step(MODEL, state, ti, row)
    times, values = state.tracking.times.copy(), state.tracking.values.copy()
    a = step(MODEL, state, t[400], v[400].tolist())
    b = step(MODEL, state, t[400], v[400].tolist())
    assert horse_frame(MODEL, a, t[400]) == horse_frame(MODEL, b, t[400])
    for ti, row in zip(t[401:600], v[401:600].tolist(), strict=True):
        a = step(MODEL, a, ti, row)
    np.testing.assert_array_equal(state.tracking.times, times)  # an old state is never modified
    np.testing.assert_array_equal(state.tracking.values, values)


_values = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-0.2, 0.2),
    st.floats(-30.0, 30.0),
)


@given(
    st.lists(
        st.tuples(st.floats(-0.01, 0.3), st.lists(_values, min_size=6, max_size=6)),
        min_size=1,
        max_size=150,
    )
)
@settings(max_examples=60, deadline=None)
def test_garbage_never_raises_and_every_frame_is_finite_and_bounded(samples) -> None:
    state, t = State(), 0.0
    for dt, row in samples:
        t += dt
        state = step(MODEL, state, t, row)
        frame = horse_frame(MODEL, state, t)
        assert all(math.isfinite(x) for x in frame)
        assert max(abs(x) for x in frame[:12]) <= 1.5  # hooves within a stride's reach and lift
        assert max(abs(x) for x in frame[12:15]) <= 10.0  # m
        assert max(abs(x) for x in frame[15:19]) <= 180.0  # deg
    assert all(math.isfinite(x) for x in RIDER.evaluate(horse_frame(MODEL, state, t)))


def test_an_imu_strap_recording_counts_its_faults_and_stays_locked() -> None:
    rec = record(gait_script("canter", 6.0, seed=3), 200.0, imperfections=IMU_STRAP, seed=3)
    assert rec.saddle.t is not None
    run = _run(rec.saddle.t, rec.saddle.values)
    counters = estimate(run.final).counters
    assert counters["losses"] == 0 and counters["glitches"] == 0 and counters["empty"] == 0
    assert counters["gaps"] == 0  # 10 % dropped at 200 Hz: never 0.2 s without a sample
    assert run.final.lock is Lock.LOCKED
