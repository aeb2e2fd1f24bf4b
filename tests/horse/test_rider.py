"""The rider driven by the procedural horse does what the thesis' section 9 reports.

Also checks the length scale: Appendix B's foot-height clamps (hoof height sums of
15 and 18 for the lower back, 15 for the feet and knees, 20 for the wrists, in rig
units) stay idle in the walk and the trot and engage in the jump and the rear.

The thesis' rules alone (``jump.weight = 0``): the ``[jump]`` layer (rules/jump.py) moves the
trunk over a fence and in a rear on top of them, and is tested in tests/rules/test_jump.py.
"""

from __future__ import annotations

import numpy as np
import pytest

from riderlive.channels import HORSE_INDEX, RIDER_INDEX
from riderlive.horse import DEFAULT_SCALE, MOVE_TABLE, Move, generate
from riderlive.horse.script import Segment, ShotScript
from riderlive.rules import RiderModel, RuleParams
from tests.horse.signals import oscillations, touchdowns

THESIS = {"jump.weight": 0.0}
RIDER = RiderModel(params=RuleParams().with_values(THESIS), scale=DEFAULT_SCALE)
UNCLAMPED = RiderModel(
    params=RuleParams().with_values(
        {
            **THESIS,
            "lower_back.front_height_limit": 1e9,
            "lower_back.back_height_limit": 1e9,
            "feet.height_limit": 1e9,
            "wrists.height_limit": 1e9,
        }
    ),
    scale=DEFAULT_SCALE,
)
LEAD_IN = 2.0


def _take(first: dict, move: str | None = None, seed: int | None = None, rate: float = 240.0):
    segments = [Segment(**first)] + ([Segment(move=move), Segment(gait="walk", seconds=1.0)] if move else [])
    return generate(ShotScript(seed=seed, segment=segments), rate)


def _sums(table) -> dict[str, np.ndarray]:
    h = {leg: table.values[:, HORSE_INDEX[f"{leg}Hoof.ty"]] * DEFAULT_SCALE for leg in ("lf", "rf", "lb", "rb")}
    front, back = h["lf"] + h["rf"], h["lb"] + h["rb"]
    return {"front": front, "back": back, "all": front + back}


def _stage(table, move: Move, name: str) -> np.ndarray:
    start, end = MOVE_TABLE[move].stage(name)
    return (table.t >= LEAD_IN + start) & (table.t < LEAD_IN + end)


def _lower_back(table) -> np.ndarray:
    return RIDER.evaluate_batch(table.values)[:, RIDER_INDEX["lower_back.rz"]]


@pytest.mark.parametrize("gait", ["walk", "trot"])
@pytest.mark.parametrize("speed_at", [0.0, 0.5, 1.0])
def test_foot_height_clamps_stay_idle_in_walk_and_trot(gait: str, speed_at: float) -> None:
    lo, hi = {"walk": (1.4, 1.8), "trot": (3.2, 4.9)}[gait]
    table = _take({"gait": gait, "seconds": 6.0, "speed": lo + speed_at * (hi - lo)}, seed=5)
    sums = _sums(table)
    assert sums["front"].max() < 18.0 and sums["back"].max() < 15.0
    assert sums["all"].max() < 15.0  # feet and knees (15) and so the wrists (20) too
    np.testing.assert_allclose(RIDER.evaluate_batch(table.values), UNCLAMPED.evaluate_batch(table.values), atol=1e-12)


@pytest.mark.parametrize("move", ["jump", "rear"])
def test_foot_height_clamps_engage_in_jump_and_rear(move: str) -> None:
    table = _take({"gait": "canter", "seconds": LEAD_IN}, move)
    sums = _sums(table)
    assert sums["front"].max() >= 18.0
    assert sums["all"].max() >= 20.0  # wrists (20), and feet and knees (15)
    if move == "jump":
        assert sums["back"].max() >= 15.0  # the hind legs tuck over the fence
    clamped, free = RIDER.evaluate_batch(table.values), UNCLAMPED.evaluate_batch(table.values)
    for channel in ("lower_back.rz", "lf_wrist.ty", "rt_foot.ry", "lf_knee.ty"):
        i = RIDER_INDEX[channel]
        assert np.max(np.abs(clamped[:, i] - free[:, i])) > 1e-3, channel


def test_lift_peaks_twice_per_trot_stride() -> None:
    table = _take({"gait": "trot", "seconds": 8.0}, rate=1000.0)
    lift = RIDER.evaluate_batch(table.values)[:, RIDER_INDEX["cog.ty"]]
    lf = touchdowns(table, 0)
    window = (table.t >= lf[0]) & (table.t < lf[-1])
    assert oscillations(lift[window]) == 2 * (len(lf) - 1)
    assert np.ptp(lift) > 0.0


def test_in_the_trot_the_rider_only_bounces() -> None:
    """Section 6.3: the hooves stay under the horse, so the rider bounces but hardly leans."""
    table = _take({"gait": "trot", "seconds": 6.0})
    rider = RIDER.evaluate_batch(table.values)
    assert np.abs(rider[:, RIDER_INDEX["lower_back.rz"]]).max() < 2.0
    assert np.ptp(rider[:, RIDER_INDEX["cog.ty"]]) * DEFAULT_SCALE > 0.5  # lift, rig units


def test_in_the_walk_the_rider_leans_forward_as_a_front_leg_lifts() -> None:
    """Section 9.6: forward as each front leg is lifted and set down in front, a rolling motion."""
    table = _take({"gait": "walk", "seconds": 8.0})
    back = _lower_back(table)
    front = table.values[:, HORSE_INDEX["lfHoof.ty"]] + table.values[:, HORSE_INDEX["rfHoof.ty"]]
    assert back[front > 0.05].mean() > back[front == 0.0].mean() + 0.5


def test_in_the_gallop_the_rider_lifts_in_the_airborne_phase() -> None:
    """Section 9.3: the rider lifts into the air when the horse's feet are off the ground."""
    table = _take({"gait": "gallop", "seconds": 6.0})
    lift = RIDER.evaluate_batch(table.values)[:, RIDER_INDEX["cog.ty"]]
    hooves = [HORSE_INDEX[f"{leg}Hoof.ty"] for leg in ("lf", "rf", "lb", "rb")]
    airborne = (table.values[:, hooves] > 0.0).all(axis=1)
    assert airborne.any()
    assert lift[airborne].mean() > 2.0 * lift[~airborne].mean()


def test_rider_leans_forward_at_take_off_and_back_at_landing() -> None:
    table = _take({"gait": "canter", "seconds": LEAD_IN, "speed": 5.5}, "jump")
    back = _lower_back(table)
    take_off, landing = back[_stage(table, Move.JUMP, "take-off")], back[_stage(table, Move.JUMP, "landing")]
    steady = back[table.t < LEAD_IN]
    assert take_off.mean() > 5.0 and take_off.max() > steady.max() + 10.0
    assert landing.mean() < -5.0 and landing.min() < steady.min() - 5.0


def test_rider_leans_back_in_the_sliding_stop() -> None:
    table = _take({"gait": "gallop", "seconds": LEAD_IN}, "stop")
    slide = _lower_back(table)[_stage(table, Move.STOP, "slide")]
    assert slide.mean() < -3.0
    assert slide.max() < 0.0


def test_rider_leans_forward_when_the_horse_rears() -> None:
    table = _take({"gait": "walk", "seconds": LEAD_IN}, "rear")
    back = _lower_back(table)
    hold = back[_stage(table, Move.REAR, "hold")]
    assert hold.min() > 10.0
    assert hold.mean() > back[table.t < LEAD_IN].max() + 10.0
