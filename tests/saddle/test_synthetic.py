"""Synthetic saddle recordings: spoiled as documented, seeded, at the scheduled rates."""

from __future__ import annotations

import numpy as np
import pytest

from riderlive.horse.script import gait_script
from riderlive.saddle.pose import saddle_matrix
from riderlive.saddle.synthetic import IMU_STRAP, Imperfections, record, sample_times

SCRIPT = gait_script("trot", 20.0, seed=1)


def test_a_perfect_sensor_records_the_horses_saddle_exactly() -> None:
    rec = record(SCRIPT, 120.0, start=0.37)
    assert rec.saddle.t is not None and rec.horse.t is not None
    assert rec.saddle.t[0] == pytest.approx(0.37) and np.all(np.diff(rec.saddle.t) > 0)
    np.testing.assert_array_equal(rec.saddle.t, rec.horse.t)
    np.testing.assert_allclose(rec.saddle.values, saddle_matrix(rec.horse.values), atol=0)


def test_the_strap_drifts_is_noisy_tilted_and_drops_frames_as_stated() -> None:
    rec = record(SCRIPT, 250.0, imperfections=IMU_STRAP, seed=5)
    assert rec.saddle.t is not None
    error = rec.saddle.values - saddle_matrix(rec.horse.values)
    elapsed = rec.saddle.t - rec.saddle.t[0]
    (drift, _), *_ = np.linalg.lstsq(np.column_stack([elapsed, np.ones_like(elapsed)]), error[:, :3], rcond=None)
    assert np.linalg.norm(drift) == pytest.approx(IMU_STRAP.drift, rel=0.02)
    detrended = error[:, :3] - np.outer(elapsed, drift)
    assert np.std(detrended, axis=0) == pytest.approx([IMU_STRAP.noise] * 3, rel=0.05)
    yaw_rate = np.polyfit(elapsed, error[:, 4], 1)[0]
    assert abs(yaw_rate) == pytest.approx(IMU_STRAP.yaw_drift, rel=0.02)
    tilt = np.mean(error[:, [3, 5]], axis=0)
    assert np.linalg.norm(tilt) == pytest.approx(IMU_STRAP.tilt, rel=0.05)
    assert np.std(error[:, 3] - tilt[0]) == pytest.approx(IMU_STRAP.angle_noise, rel=0.05)
    kept = len(rec.saddle.t) / round(20.0 * 250.0)
    assert kept == pytest.approx(1.0 - IMU_STRAP.dropout, abs=0.015)


def test_same_seed_same_recording_other_seed_other() -> None:
    a = record(SCRIPT, 120.0, imperfections=IMU_STRAP, seed=3)
    b = record(SCRIPT, 120.0, imperfections=IMU_STRAP, seed=3)
    c = record(SCRIPT, 120.0, imperfections=IMU_STRAP, seed=4)
    np.testing.assert_array_equal(a.saddle.values, b.saddle.values)
    assert a.saddle.values.shape != c.saddle.values.shape or not np.array_equal(a.saddle.values, c.saddle.values)


def test_rate_schedules() -> None:
    t = sample_times([(1.0, 10.0), (2.0, 1000.0), (3.0, 50.0)], 0.0, 3.0)
    gaps = np.diff(t)
    assert np.all(gaps > 0)
    assert np.sum(np.isclose(gaps, 0.1)) == 10 and np.sum(np.isclose(gaps, 0.001)) >= 998
    assert np.sum(np.isclose(gaps, 0.02)) >= 48
    with pytest.raises(ValueError, match="10-1000 Hz"):
        sample_times(5.0, 0.0, 1.0)
    with pytest.raises(ValueError, match="empty"):
        record(SCRIPT, 120.0, start=30.0)


@pytest.mark.parametrize("field", ["drift", "noise", "dropout"])
def test_imperfections_are_validated(field: str) -> None:
    with pytest.raises(ValueError, match=field):
        Imperfections(**{field: -1.0})
    with pytest.raises(ValueError, match=field):
        Imperfections(**{field: float("nan")})
