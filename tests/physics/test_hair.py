"""Section 8.9: the hair attributes drive the braid ("up and down as the sum of the height of all feet")."""

from __future__ import annotations

import math

import numpy as np
import pytest

from riderlive.channels import HORSE_INDEX, HORSE_NAMES, RIDER_INDEX, RIDER_NAMES
from riderlive.horse import DEFAULT_SCALE, generate_gait
from riderlive.physics.attach import BRAID, Body
from riderlive.physics.config import load_physics
from riderlive.rules import RiderModel

CONFIG = load_physics()
BODY = Body(CONFIG.horse, CONFIG.rider)


def braid_direction(hair_up: float = 0.0, hair_side: float = 0.0, horse: np.ndarray | None = None) -> np.ndarray:
    rider = np.zeros(len(RIDER_NAMES))
    rider[RIDER_INDEX["hair.up"]] = hair_up
    rider[RIDER_INDEX["hair.side"]] = hair_side
    h = np.zeros(len(HORSE_NAMES)) if horse is None else horse
    return np.asarray(BODY.pose(h, rider).rotations[BRAID][:, 0])


def angle(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(min(1.0, float(a @ b / np.linalg.norm(a) / np.linalg.norm(b)))))


def test_the_attributes_tilt_the_braids_tie_by_their_gains() -> None:
    rest = braid_direction()
    up = braid_direction(hair_up=4.0)
    assert angle(rest, up) == pytest.approx(4.0 * CONFIG.rider.hair_up_gain, abs=1e-9)
    assert up[1] > rest[1] and up[0] < rest[0]  # up and back
    side = braid_direction(hair_side=0.5)
    across = angle(rest[1:], side[1:])  # a turn about the head's x: exact in the y-z plane
    assert across == pytest.approx(0.5 * CONFIG.rider.hair_side_gain, abs=1e-9)
    assert side[2] > rest[2]  # to the rider's right


def test_the_braid_rises_and_falls_with_the_hooves_in_the_trot() -> None:
    take = generate_gait("trot", 2.0, 60.0)
    rider = RiderModel(scale=DEFAULT_SCALE).evaluate_batch(take.values)
    heights = sum(take.values[:, HORSE_INDEX[f"{h}Hoof.ty"]] for h in ("lf", "rf", "lb", "rb"))
    elevation = [braid_direction(r[RIDER_INDEX["hair.up"]], r[RIDER_INDEX["hair.side"]])[1] for r in rider]
    assert np.corrcoef(heights, elevation)[0, 1] > 0.99
