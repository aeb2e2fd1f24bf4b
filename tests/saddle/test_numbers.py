"""The issue's numbers: lock within 2 strides, rider correlation >= 0.9 (>= 0.85 from an IMU strap),
re-lock within 2 strides of a gait change, rate changes, a start mid-stride.

Every case is seeded (speed within the gait's range, sample rate, start phase, the
horse's stride-to-stride variation, the sensor's faults). The full table is
``bench/bench_saddle_table.py``'s, in ``docs/saddle.md``.
"""

from __future__ import annotations

import numpy as np
import pytest

from riderlive.horse import GAIT_TABLE, GAITS, Gait
from riderlive.horse.curves import SCALAR
from riderlive.horse.layers import GaitLayer
from riderlive.horse.script import Segment, ShotScript, gait_script
from riderlive.saddle.estimator import Model
from riderlive.saddle.synthetic import IMU_STRAP
from riderlive.saddle.trial import GaitCase, trial

MODEL = Model()


def _stride_hz(gait: str) -> float:
    spec = GAIT_TABLE[Gait(gait)]
    return spec.frequency_at(spec.default_speed)


@pytest.mark.parametrize("gait", GAITS)
@pytest.mark.parametrize(("faults", "floor"), [(None, 0.9), (IMU_STRAP, 0.85)], ids=["clean", "imu-strap"])
def test_lock_within_two_strides_then_the_rider_follows(gait: str, faults, floor: float) -> None:
    case = GaitCase.draw(gait, seed=1)
    run = case.run(7.0, faults, MODEL)
    locked = run.locked_from(gait)
    assert locked is not None, run.rebuilt.lock[-1]
    hooves_in = locked + MODEL.ease_time(case.stride_hz)
    assert (hooves_in - run.t[0]) * case.stride_hz <= 2.0
    for channel, value in run.correlations(hooves_in).items():
        assert value >= floor, (channel, value)


@pytest.mark.parametrize("gait", GAITS)
def test_phase_and_frequency_after_lock(gait: str) -> None:
    case = GaitCase.draw(gait, seed=2)
    run = case.run(6.0, None, MODEL)
    script = gait_script(gait, 6.0, case.speed, seed=case.seed + 1)
    layer = script.start(script.model()).layer
    assert isinstance(layer, GaitLayer)
    locked = run.locked_from(gait)
    assert locked is not None
    rows = run.t >= locked
    true_phase = np.array([layer.phase(t, SCALAR)[0] for t in run.t[rows]])
    error = (run.rebuilt.phase[rows] - true_phase + 0.5) % 1.0 - 0.5
    assert np.max(np.abs(error)) <= 0.02  # strides
    assert np.max(np.abs(run.rebuilt.stride_hz[rows] / case.stride_hz - 1.0)) <= 0.01


@pytest.mark.parametrize(
    ("before", "after", "strides"),
    [
        ("walk", "trot", 2.0),
        ("trot", "walk", 2.0),
        ("trot", "canter", 2.0),
        ("canter", "trot", 2.0),
        ("gallop", "canter", 2.0),
        # the horse's gallop starts at 2.0 Hz, the canter's top frequency, and the two look
        # alike at the saddle: the label waits for the speed to rise (docs/saddle.md)
        ("canter", "gallop", 2.5),
    ],
)
def test_relock_within_two_strides_of_a_gait_change(before: str, after: str, strides: float) -> None:
    change = 5.0
    script = ShotScript(seed=4, segment=[Segment(gait=before, seconds=change), Segment(gait=after, seconds=4.0)])
    run = trial(script, 120.0, start=0.2, imperfections=IMU_STRAP, seed=4, model=MODEL)
    assert run.rebuilt.gait[int(np.searchsorted(run.t, change))] == before
    locked = run.locked_from(after, after=change)
    assert locked is not None
    stride_hz = _stride_hz(after)
    hooves_in = locked + MODEL.ease_time(stride_hz)
    assert (hooves_in - change) * stride_hz <= strides
    for channel, value in run.correlations(hooves_in).items():
        assert value >= 0.85, (channel, value)


def test_rate_changes_from_1000_to_10_hz_keep_the_lock() -> None:
    schedule = [(3.0, 1000.0), (6.0, 10.0), (9.0, 250.0), (12.0, 60.0)]
    run = trial(gait_script("trot", 12.0, seed=6), schedule, start=0.3, imperfections=IMU_STRAP, seed=6, model=MODEL)
    locked = run.locked_from("trot")
    assert locked is not None and locked < 2.0
    assert run.rebuilt.final.tracking.counters.losses == 0
    for channel, value in run.correlations(locked + 0.3).items():
        assert value >= 0.85, (channel, value)


def test_the_estimate_is_data_the_service_can_publish() -> None:
    import orjson

    from riderlive.saddle.estimate import estimate

    run = GaitCase.draw("canter", seed=3).run(4.0, IMU_STRAP, MODEL)
    published = estimate(run.rebuilt.final).as_dict()
    assert published["gait"] == "canter" and published["lock"] == "locked"
    assert GAIT_TABLE[Gait.CANTER].frequency[0] <= published["stride_hz"] <= GAIT_TABLE[Gait.CANTER].frequency[1]
    assert 0.0 <= published["phase"] < 1.0 and published["score"] > 0.85 and published["age"] == 0.0
    assert set(published["counters"]) >= {"samples", "missing", "gaps", "glitches", "rebases", "locks", "losses"}
    assert orjson.loads(orjson.dumps(published)) == published
