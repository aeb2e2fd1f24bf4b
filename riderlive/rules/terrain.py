"""Thesis section 10: the rules on sloping ground.

Appendix B assumes "a flat ground plane". On sloping ground the horse frame carries the
ground under the horse in two optional channels (``channels.HORSE_GROUND``):
``ground.rz``, its pitch (deg, + rising ahead), and ``ground.ty``, its height. Of the
thirteen channels the rules read (``RULE_INPUTS``), only one sees the ground:

- ``rearPivot.rz`` is the trunk's pitch in the world, so it holds the ground's pitch
  (the rig has no root pitch: the body is pitched at its rear pivot). The rules' pitch
  terms (Eq. 1, 5, 8, 12-14) stand for the trunk's rocking over its legs, which is the
  pitch relative to the ground: :func:`ground_relative` takes ``ground.rz`` out of it.
- The hooves' ``tx`` / ``ty`` are measured along and above the local ground (a hoof on
  the slope is at height 0), ``rearPivot.tx`` / ``ty`` are the hips' displacement from
  standing on it, ``rearPivot.rx`` is the roll about the travel direction, ``backMid.rz``
  the back's own bend: all already relative to the ground, unchanged.
- ``root.*`` and ``ground.ty`` (world placement) are not read by the rules.

So on a constant slope the rules see what they see on the flat. The rider's own answer
to the slope is the ``[terrain]`` preset part (:func:`lean`), added to
``lower_back.rz`` after the rules: her pelvis sits on the saddle, which pitches with the
horse, so taking the ground's pitch back out (``upright`` 1) keeps her trunk's world
attitude as on the flat, and ``uphill_lean`` / ``downhill_lean`` lean it forward on a
rise and back on a descent (``docs/rules.md``, "Terrain").

Both functions are pure and run on floats and NumPy arrays alike; a frame without the
ground channels, or with ``ground.rz`` 0, is the flat ground of Appendix B (the engine
skips this module then, so the flat result is bit-identical).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from riderlive.channels import HORSE_INDEX, RIDER_INDEX
from riderlive.rules.kuhnel2003 import RULE_INPUTS
from riderlive.rules.params import Terrain

GROUND_PITCH = HORSE_INDEX["ground.rz"]
"""Column of ``ground.rz`` in a horse frame."""
GROUND_RELATIVE: tuple[str, ...] = ("rearPivot.rz",)
"""The horse channels :func:`ground_relative` changes: the ground's pitch is taken out of them."""
PITCH_COLUMN = HORSE_INDEX["rearPivot.rz"]
PITCH_ARGUMENT = RULE_INPUTS.index("rearPivot.rz")
"""Position of ``rearPivot.rz`` among the rules' arguments."""
LEAN_OUTPUT = RIDER_INDEX["lower_back.rz"]
"""The rider channel the ``[terrain]`` lean is added to."""


def ground_pitch(horse: Sequence[float]) -> float:
    """``ground.rz`` of a horse frame (deg), 0 for a frame from before the ground channels."""
    return horse[GROUND_PITCH] if len(horse) > GROUND_PITCH else 0.0


def ground_relative(horse: Sequence[float]) -> list[float]:
    """The horse frame the rules read: ``rearPivot.rz`` relative to the ground (``ground.rz``
    taken out); every other channel as given. Flat ground returns an equal copy."""
    out = list(horse)
    out[PITCH_COLUMN] -= ground_pitch(horse)
    return out


def ground_relative_columns(horse: Any) -> Any:
    """:func:`ground_relative` of an (N, len(HORSE)) array (a new array)."""
    out = np.array(horse, dtype=np.float64)
    out[:, PITCH_COLUMN] -= out[:, GROUND_PITCH]
    return out


def lean(p: Terrain, pitch: Any) -> Any:
    """The rider's answer to ground pitch ``pitch`` (deg, float or array): degrees added to
    ``lower_back.rz`` (+ forward), ``(upright + uphill_lean) * pitch`` on a rise and
    ``(upright + downhill_lean) * pitch`` on a descent."""
    if isinstance(pitch, np.ndarray):
        return (p.upright + np.where(pitch > 0.0, p.uphill_lean, p.downhill_lean)) * pitch
    return (p.upright + (p.uphill_lean if pitch > 0.0 else p.downhill_lean)) * pitch
