"""The saddle pose: hand-computed poses, scalar = batch, the inverse, and the horse's saddle vs biomechanics."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.channels import HORSE, HORSE_INDEX, SADDLE_INDEX, SADDLE_NAMES, Kind, lookup
from riderlive.horse import GAITS, WITHERS_HEIGHT, generate_gait
from riderlive.horse.gaits import GAIT_TABLE, Gait
from riderlive.saddle.pose import (
    ARRAY,
    BACK_MID,
    SCALAR,
    SaddlePoint,
    saddle_from_horse,
    saddle_from_trunk,
    saddle_matrix,
    trunk_from_saddle,
)
from tests.horse.signals import oscillations

D = math.radians
POINT = SaddlePoint()  # 0.60 m ahead of the rear pivot, 0.15 m above it


def _frame(**values: float) -> list[float]:
    frame = [0.0] * len(HORSE)
    for name, value in values.items():
        frame[HORSE_INDEX[name.replace("_", ".", 1)]] = value
    return frame


def test_channels_are_metres_and_degrees_on_their_own_node() -> None:
    assert SADDLE_NAMES == ("saddle.tx", "saddle.ty", "saddle.tz", "saddle.rx", "saddle.ry", "saddle.rz")
    assert [lookup(n).kind for n in SADDLE_NAMES] == [Kind.TRANSLATION] * 3 + [Kind.ROTATION] * 3


def test_standing_square_is_zero() -> None:
    assert saddle_from_horse([0.0] * len(HORSE)) == [0.0] * 6


def test_hips_translate_the_saddle_one_to_one() -> None:
    out = saddle_from_horse(_frame(rearPivot_tx=0.01, rearPivot_ty=-0.02, rearPivot_tz=0.03))
    np.testing.assert_allclose(out, [0.01, -0.02, 0.03, 0, 0, 0], atol=1e-15)


def test_pitch_nose_up_lifts_the_saddle_ahead_of_the_hips() -> None:
    out = saddle_from_horse(_frame(rearPivot_rz=10.0))
    f, u = POINT.forward, POINT.up
    expected_x = f * math.cos(D(10)) - u * math.sin(D(10)) - f
    expected_y = f * math.sin(D(10)) + u * math.cos(D(10)) - u
    np.testing.assert_allclose(out, [expected_x, expected_y, 0.0, 0.0, 0.0, 10.0], atol=1e-12)


def test_roll_right_moves_the_raised_saddle_right_and_yaw_left_moves_it_left() -> None:
    rolled = saddle_from_horse(_frame(rearPivot_rx=5.0))
    assert rolled[SADDLE_INDEX["saddle.tz"]] == pytest.approx(POINT.up * math.sin(D(5)))
    assert rolled[SADDLE_INDEX["saddle.rx"]] == pytest.approx(5.0)
    yawed = saddle_from_horse(_frame(rearPivot_ry=4.0))
    assert yawed[SADDLE_INDEX["saddle.tz"]] == pytest.approx(-POINT.forward * math.sin(D(4)))
    assert yawed[SADDLE_INDEX["saddle.ry"]] == pytest.approx(4.0)


def test_the_back_bend_tilts_a_saddle_on_the_front_segment_only() -> None:
    bent = saddle_from_horse(_frame(backMid_rz=4.0))
    ahead = POINT.forward - BACK_MID
    y = ahead * math.sin(D(4)) + POINT.up * math.cos(D(4)) - POINT.up
    assert bent[SADDLE_INDEX["saddle.ty"]] == pytest.approx(y)
    assert bent[SADDLE_INDEX["saddle.rz"]] == pytest.approx(4.0)
    rear = saddle_from_horse(_frame(backMid_rz=4.0), SaddlePoint(forward=0.3, up=0.1))
    assert rear == [0.0] * 6


@given(
    st.lists(st.floats(-0.5, 0.5), min_size=3, max_size=3),
    st.lists(st.floats(-60.0, 60.0), min_size=3, max_size=3),
    st.floats(-30.0, 30.0),
    st.floats(0.0, 0.95),
    st.floats(-0.3, 0.5),
)
@settings(max_examples=200, deadline=None)
def test_inverse_round_trip_and_scalar_equals_batch(
    t: list[float], r: list[float], bend: float, forward: float, up: float
) -> None:
    point = SaddlePoint(forward=forward, up=up)
    trunk = (*t, *r)
    saddle = saddle_from_trunk(trunk, bend, point, SCALAR)
    back = trunk_from_saddle(saddle, bend, point, SCALAR)
    np.testing.assert_allclose(back, trunk, atol=1e-9)
    batch = saddle_from_trunk([np.array([v, v]) for v in trunk], np.array([bend, bend]), point, ARRAY)
    np.testing.assert_allclose([np.asarray(v)[1] for v in batch], saddle, rtol=0, atol=1e-12)


def test_batch_equals_live_on_a_take() -> None:
    take = generate_gait("canter", 2.0, 120.0, seed=3)
    batch = saddle_matrix(take.values)
    live = np.array([saddle_from_horse(list(row)) for row in take.values])
    np.testing.assert_allclose(batch, live, rtol=0, atol=1e-12)


def _strides(gait: str, count: int = 4, rate: float = 1000.0) -> np.ndarray:
    """``count`` whole strides of the saddle, from the lowest point of the first."""
    spec = GAIT_TABLE[Gait(gait)]
    n = round(rate / spec.frequency_at(spec.default_speed))
    saddle = saddle_matrix(generate_gait(gait, (count + 2) / spec.frequency_at(spec.default_speed), rate).values)
    start = int(np.argmin(saddle[:n, SADDLE_INDEX["saddle.ty"]]))
    return saddle[start : start + count * n + 1]


def _dominant_harmonic(y: np.ndarray, strides: int) -> int:
    """Oscillations per stride of the strongest component of ``y`` over whole strides."""
    spectrum = np.abs(np.fft.rfft(y[:-1] - y[:-1].mean()))
    return int(np.argmax(spectrum)) // strides


def test_trot_saddle_rises_twice_per_stride_by_four_to_five_percent_of_the_withers() -> None:
    y = _strides("trot")[:, SADDLE_INDEX["saddle.ty"]]
    assert 0.04 <= np.ptp(y) / WITHERS_HEIGHT <= 0.05
    assert oscillations(y) == 2 * 4
    assert _dominant_harmonic(y, 4) == 2


def test_trot_saddle_side_to_side_within_measured_14_to_24_mm() -> None:
    saddle = _strides("trot")
    assert 0.014 <= np.ptp(saddle[:, SADDLE_INDEX["saddle.tz"]]) <= 0.024


def test_canter_saddle_rises_once_per_stride() -> None:
    y = _strides("canter")[:, SADDLE_INDEX["saddle.ty"]]
    assert oscillations(y) == 4
    assert _dominant_harmonic(y, 4) == 1


@pytest.mark.parametrize("gait", GAITS)
def test_pitch_is_the_saddles_dominant_rotation(gait: str) -> None:
    saddle = _strides(gait)
    pitch, roll, yaw = (np.ptp(saddle[:, SADDLE_INDEX[f"saddle.{a}"]]) for a in ("rz", "rx", "ry"))
    assert pitch > roll and pitch > yaw


def test_walk_saddle_pitch_within_seven_degrees() -> None:
    saddle = _strides("walk")
    assert 4.0 <= np.ptp(saddle[:, SADDLE_INDEX["saddle.rz"]]) <= 7.0
