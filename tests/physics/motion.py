"""Horse takes for the physics tests, from the procedural horse (and two synthetic ones).

Frames are in ``channels.HORSE`` order (metres, degrees; pivot and hoof channels are
displacements from standing, as the procedural horse writes them).
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np

from riderlive.channels import HORSE_INDEX, HORSE_NAMES
from riderlive.horse import ProceduralHorse
from riderlive.physics.drive import Drive, TakeSource

RATE = 240.0

SCRIPTS: dict[str, tuple[str, tuple[tuple[float, str, str], ...], float]] = {
    # kind: (starting gait, ((time, "gait" | "move", name), ...), duration in seconds)
    "gallop": ("gallop", (), 3.0),
    "buck": ("trot", ((0.8, "move", "buck"),), 3.5),
    "trot_rear_gallop": ("trot", ((2.0, "move", "rear"), (5.4, "gait", "gallop")), 8.0),
}


@cache
def horse_take(kind: str) -> tuple[np.ndarray, np.ndarray]:
    """(times, frames) of a procedural horse take, sampled at 240 Hz."""
    gait, commands, duration = SCRIPTS[kind]
    horse = ProceduralHorse(gait)
    times = np.arange(round(duration * RATE) + 1) / RATE
    pending = list(commands)
    frames = []
    for t in times:
        while pending and pending[0][0] <= t:
            _, what, name = pending.pop(0)
            if what == "move":
                horse.perform(name)
            else:
                horse.set_gait(name)
        frames.append(horse.sample(float(t)))
    return times, np.array(frames)


def source(kind: str) -> TakeSource:
    times, frames = horse_take(kind)
    return TakeSource(times, frames)


def standing(t: float) -> Drive:
    """A horse standing still."""
    return Drive(np.zeros(len(HORSE_NAMES)))


def planar(t: float) -> Drive:
    """Horse motion in the vertical x-y plane only: forward surge, heave and pitch."""
    f = np.zeros(len(HORSE_NAMES))
    f[HORSE_INDEX["root.tx"]] = 4.0 * t + 0.3 * math.sin(5.0 * t)
    f[HORSE_INDEX["rearPivot.ty"]] = 0.1 * math.sin(9.0 * t)
    f[HORSE_INDEX["rearPivot.rz"]] = 25.0 * math.sin(3.0 * t)
    return Drive(f)
