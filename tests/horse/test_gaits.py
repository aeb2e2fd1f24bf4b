"""Footfalls, duty factors, stride frequencies and trunk motion of the four gaits."""

from __future__ import annotations

import numpy as np
import pytest

from riderlive.channels import HORSE_INDEX
from riderlive.horse import GAIT_TABLE, GAITS, WITHERS_HEIGHT, Gait, generate_gait
from tests.horse.signals import GROUND, count_runs, heights, oscillations, touchdowns

RATE = 1000.0
LF, RF, LB, RB = range(4)

# Published ranges (docs/horse.md): speed m/s, stride frequency Hz, duty factor.
PUBLISHED = {
    "walk": ((1.4, 1.8), (0.67, 1.0), (0.55, 0.70)),
    "trot": ((3.2, 4.9), (0.92, 1.5), (0.30, 0.50)),
    "canter": ((3.3, 6.0), (1.33, 2.0), (0.30, 0.50)),
    "gallop": ((9.0, 17.0), (2.0, 2.4), (0.15, 0.35)),
}


def test_gait_names_are_the_contract() -> None:
    assert GAITS == ("walk", "trot", "canter", "gallop")


def _take(gait: str, seconds: float = 8.0, speed: float | None = None):
    return generate_gait(gait, seconds, RATE, speed=speed)


@pytest.mark.parametrize("gait", GAITS)
def test_duty_factor_within_published_range(gait: str) -> None:
    down = heights(_take(gait)) <= GROUND
    lo, hi = PUBLISHED[gait][2]
    for leg in range(4):
        assert lo <= down[:, leg].mean() <= hi, (gait, leg, down[:, leg].mean())


def test_walk_is_a_four_beat_lateral_sequence_on_two_or_three_hooves() -> None:
    table = _take("walk")
    down = (heights(table) <= GROUND).sum(axis=1)
    assert down.min() == 2 and down.max() == 3
    events = sorted((t, leg) for leg in range(4) for t in touchdowns(table, leg))
    order = [leg for _, leg in events]
    start = order.index(LB)
    cycle = order[start : start + 8]
    assert cycle == [LB, LF, RB, RF, LB, LF, RB, RF]  # left hind, left fore, right hind, right fore
    gaps = np.diff([t for t, _ in events])
    assert gaps.min() > 0.2  # four separate beats


def test_trot_diagonal_pairs_strike_together_with_suspension() -> None:
    table = _take("trot")
    for a, b in ((LF, RB), (RF, LB)):
        ta, tb = touchdowns(table, a), touchdowns(table, b)
        assert len(ta) == len(tb) >= 6
        assert np.max(np.abs(ta - tb)) <= 1.0 / RATE
    lf, rf = touchdowns(table, LF), touchdowns(table, RF)
    period = np.mean(np.diff(lf))
    offset = (rf[0] - lf[0]) % period
    assert abs(offset / period - 0.5) < 0.01  # two beats, half a stride apart
    airborne = (heights(table) > GROUND).all(axis=1)
    window = (table.t >= lf[0]) & (table.t < lf[-1])
    assert count_runs(airborne[window]) == 2 * (len(lf) - 1)  # a suspension after each beat


def test_canter_is_three_beats_with_one_suspension() -> None:
    table = _take("canter")
    t_rb, t_lb, t_rf, t_lf = (touchdowns(table, leg) for leg in (RB, LB, RF, LF))
    assert np.max(np.abs(t_lb - t_rf)) <= 1.0 / RATE  # the diagonal beat
    period = np.mean(np.diff(t_rb))
    beats = sorted({round(((t - t_rb[0]) % period) / period, 2) for t in (t_rb[1], t_lb[1], t_rf[1], t_lf[1])})
    assert len(beats) == 3
    airborne = (heights(table) > GROUND).all(axis=1)
    window = (table.t >= t_rb[0]) & (table.t < t_rb[-1])
    assert count_runs(airborne[window]) == len(t_rb) - 1


def test_gallop_never_more_than_two_down_and_one_airborne_phase_per_stride() -> None:
    table = _take("gallop", 6.0)
    down = (heights(table) <= GROUND).sum(axis=1)
    assert down.max() <= 2
    rb = touchdowns(table, RB)
    strides = len(rb) - 1
    assert strides >= 10
    window = (table.t >= rb[0]) & (table.t < rb[-1])
    assert count_runs(down[window] == 0) == strides
    beats = [touchdowns(table, leg)[2] for leg in range(4)]
    assert len({round(b, 3) for b in beats}) == 4  # four-beat


@pytest.mark.parametrize("gait", GAITS)
@pytest.mark.parametrize("where", [0.0, 0.37, 1.0])
def test_stride_frequency_matches_request_within_two_percent(gait: str, where: float) -> None:
    (v0, v1), (f0, f1), _ = PUBLISHED[gait]
    speed = v0 + where * (v1 - v0)
    expected = f0 + where * (f1 - f0)  # the documented linear law
    lf = touchdowns(_take(gait, 8.0, speed), LF)
    measured = 1.0 / np.mean(np.diff(lf))
    assert abs(measured / expected - 1.0) < 0.02
    assert GAIT_TABLE[Gait(gait)].frequency_at(speed) == pytest.approx(expected)


def test_hooves_do_not_slip_in_support() -> None:
    table = _take("trot")
    tx = table.values[:, HORSE_INDEX["lfHoof.tx"]]
    root = table.values[:, HORSE_INDEX["root.tx"]]
    down = heights(table)[:, LF] <= GROUND
    world = tx + root
    still = down[1:] & down[:-1]
    assert np.max(np.abs(np.diff(world)[still])) < 1e-9


def _per_stride(table, channel: str):
    lf = touchdowns(table, LF)
    window = (table.t >= lf[0]) & (table.t < lf[-1])
    return table.values[window, HORSE_INDEX[channel]], len(lf) - 1


def test_trot_trunk_rises_twice_per_stride_by_four_to_five_percent() -> None:
    table = _take("trot", 8.0)
    y, strides = _per_stride(table, "rearPivot.ty")
    travel = (y.max() - y.min()) / WITHERS_HEIGHT
    assert 0.04 <= travel <= 0.05
    assert oscillations(y) == 2 * strides


def test_canter_trunk_rises_once_per_stride() -> None:
    table = _take("canter", 8.0)
    y, strides = _per_stride(table, "rearPivot.ty")
    assert oscillations(y) == strides


@pytest.mark.parametrize("gait", ["walk", "trot", "canter"])
def test_trunk_pitch_within_twenty_degrees(gait: str) -> None:
    pitch = _take(gait).values[:, HORSE_INDEX["rearPivot.rz"]]
    assert np.abs(pitch).max() <= 20.0
    assert np.abs(pitch).max() >= 1.0  # and it does pitch
