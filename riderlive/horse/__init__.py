"""The procedural horse (placeholder until the gait generator lands).

Contract kept by the real generator:

- ``DEFAULT_SCALE``: thesis rig units per metre, the default length scale for a
  horse produced here.
- ``GAITS``: the gait names; ``ProceduralHorse(gait, speed, seed)`` is a live source
  whose ``sample(t)`` returns one frame in ``channels.HORSE`` order (metres,
  degrees) for time ``t`` in seconds (non-decreasing), and whose
  ``set_gait(gait, speed)`` changes gait at any time without a jump.
"""

from __future__ import annotations

import math

from riderlive.channels import HORSE_INDEX, HORSE_NAMES

DEFAULT_SCALE = 25.0
GAITS: tuple[str, ...] = ("walk", "trot", "canter", "gallop")


class ProceduralHorse:
    """A live horse source: one frame per call of :meth:`sample`."""

    def __init__(self, gait: str = "trot", speed: float | None = None, seed: int | None = None) -> None:
        self.gait = gait
        self.speed = speed if speed is not None else 4.0
        self.seed = seed

    def set_gait(self, gait: str, speed: float | None = None) -> None:
        if gait not in GAITS:
            raise ValueError(f"unknown gait {gait!r}; choose one of {', '.join(GAITS)}")
        self.gait = gait
        if speed is not None:
            self.speed = speed

    def sample(self, t: float) -> list[float]:
        frame = [0.0] * len(HORSE_NAMES)
        phase = 2.0 * math.pi * 1.2 * t
        for hoof, offset, base in (("lf", 0.0, 0.6), ("rb", 0.0, -0.6), ("rf", math.pi, 0.6), ("lb", math.pi, -0.6)):
            frame[HORSE_INDEX[f"{hoof}Hoof.tx"]] = base + 0.35 * math.sin(phase + offset)
            frame[HORSE_INDEX[f"{hoof}Hoof.ty"]] = max(0.0, 0.12 * math.sin(phase + offset))
        frame[HORSE_INDEX["rearPivot.ty"]] = 1.0 + 0.03 * math.cos(2.0 * phase)
        frame[HORSE_INDEX["rearPivot.rz"]] = 2.0 * math.sin(phase)
        frame[HORSE_INDEX["root.tx"]] = self.speed * t
        return frame
