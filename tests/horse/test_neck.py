"""The horse's neck and head: they nod in the walk and the canter and are steady in the trot.

Sources (docs/horse.md): the head and neck swing as a balancing pendulum in the
four-beat walk and the canter, and the head is held steady in the trot (Dunbar et al.
2008, J Exp Biol 211: head-neck pitch excursions smallest at the trot; a head nod at the
trot is the classic sign of a lame horse, Buchner et al. 1996, Equine Vet J 28).
Section 5 of the thesis gives the movements' head carriage (5.1 jump, 5.4 rear, 5.6 buck).
"""

from __future__ import annotations

import numpy as np
import pytest

from riderlive.channels import HORSE_INDEX, HORSE_NECK_HEAD
from riderlive.horse import GAIT_TABLE, MOVE_TABLE, ProceduralHorse, generate_gait
from riderlive.horse.curves import ARRAY, SCALAR
from riderlive.horse.gaits import Gait
from riderlive.horse.moves import Move
from riderlive.skeleton import HORSE_RIG, horse_pose, quat

NECK, SIDE, HEAD = (HORSE_INDEX[n] for n in HORSE_NECK_HEAD)


def nod(values: np.ndarray) -> np.ndarray:
    """The head's pitch relative to the trunk: neck at the withers plus head at the poll (deg)."""
    return values[:, NECK] + values[:, HEAD]


def strides(gait: str, seconds: float) -> float:
    return GAIT_TABLE[Gait(gait)].frequency_at(GAIT_TABLE[Gait(gait)].default_speed) * seconds


@pytest.mark.parametrize(("gait", "per_stride"), [("walk", 2), ("canter", 1), ("gallop", 1)])
def test_the_head_nods_in_the_walk_and_the_canter(gait: str, per_stride: int) -> None:
    take = generate_gait(gait, 6.0, 120.0)
    pitch = nod(take.values)
    assert np.ptp(pitch) >= 6.0  # degrees, peak to peak
    lowest = np.flatnonzero((pitch[1:-1] < pitch[:-2]) & (pitch[1:-1] <= pitch[2:]))
    assert len(lowest) == pytest.approx(per_stride * strides(gait, 6.0), abs=1.0)


def test_the_head_is_steady_in_the_trot() -> None:
    trot = np.ptp(nod(generate_gait("trot", 6.0, 120.0).values))
    walk = np.ptp(nod(generate_gait("walk", 6.0, 120.0).values))
    canter = np.ptp(nod(generate_gait("canter", 6.0, 120.0).values))
    assert trot <= 1.5 and trot < walk / 4 and trot < canter / 4


@pytest.mark.parametrize(
    ("move", "stage", "direction"),
    [("jump", "flight", -1.0), ("rear", "hold", 1.0), ("buck", "buck left", -1.0), ("stop", "slide", 1.0)],
)
def test_movements_carry_the_head_as_section_5_says(move: str, stage: str, direction: float) -> None:
    """5.1 the neck reaches forward (down) in flight; 5.4 the head leans back; 5.6 head down; 5.5 forehand up."""
    spec = MOVE_TABLE[Move(move)]
    start, end = spec.stage(stage)
    tau = np.linspace(start, end, 50)
    neck = np.array(spec.head_spline.at(tau, ARRAY))[0]
    extreme = neck.min() if direction < 0 else neck.max()
    assert direction * extreme >= 8.0
    end_values = spec.head_spline.at(spec.duration, SCALAR)
    assert end_values == pytest.approx([0.0, 0.0, 0.0], abs=1e-12)  # the move ends at rest


def test_live_and_batch_agree_and_changes_stay_smooth() -> None:
    horse = ProceduralHorse("walk")
    times = np.arange(0.0, 4.0, 1.0 / 240.0)
    live = []
    for t in times:
        if abs(t - 1.5) < 1e-9:
            horse.set_gait("canter")
        if abs(t - 2.5) < 1e-9:
            horse.perform("buck")
        live.append(horse.sample(float(t)))
    values = np.array(live)[:, [NECK, SIDE, HEAD]]
    step = np.abs(np.diff(values, axis=0)).max()
    assert step < 2.0  # degrees per 1/240 s: no jump across the gait change or into the buck


def test_the_skeletons_neck_and_head_follow_the_channels() -> None:
    rest = horse_pose({})
    names = HORSE_RIG.names
    mouth = names.index("muzzle")
    down = horse_pose({"horseNeck.rz": -30.0})
    nose_up = horse_pose({"horseHead.rz": 20.0})
    left = horse_pose({"horseNeck.ry": 15.0})
    assert down.world_positions[mouth][1] < rest.world_positions[mouth][1] - 0.2
    assert nose_up.world_positions[mouth][0] > rest.world_positions[mouth][0] + 0.05
    assert left.world_positions[mouth][2] < rest.world_positions[mouth][2] - 0.1  # +z is the right
    shoulders = names.index("shoulders")
    assert quat.norm(quat.sub(down.world_positions[shoulders], rest.world_positions[shoulders])) < 1e-12
