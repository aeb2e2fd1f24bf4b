"""Over a fence: the fold, the release and the landing that Appendix B leaves out (``[jump]``).

The thesis' lower back (Eq. 1) leans the rider back as the hooves gather under the horse
and clamps the hoof heights "to keep a rear or a jump from folding the rider"; over a
fence that gives a trunk leaning back ~27 deg at take-off and folded onto the neck in the
air (the pitch term, ``pitch * (height + 2)``, grows with the horse's height). A rider
jumping folds forward from the hip as the forehand rises (take-off), stays folded while
the horse is in the air, and opens up and sits back as the forelegs land. This layer says
so, on the rules' output, before the animator layer (like ``[terrain]``):

- ``rise`` (0-1): the forehand rising: the horse's pitch (``rearPivot.rz``) beyond
  ``pitch_from`` (gaits reach 7 deg) unless its hindquarters sit down (``rearPivot.ty``
  below ``-sit_from``, fully at ``-sit_full``: a sliding stop pitches up 12 deg with the
  front hooves on the ground, and is left to the rules, which lean the rider back), or
  the front hooves' height sum beyond ``hooves_from`` (a gallop lifts a pair to 14
  thesis units); smoothstep to ``pitch_full`` / ``hooves_full``;
- ``hind`` (0-1): the hind hooves' height sum the same way (the landing, a buck);
- the world lean aimed at (deg, + forward of upright): ``fold`` while rising or in the
  air, ``land`` when only the hind hooves are high: ``fold * rise + land * (1 - rise) * hind``;
- the trunk's bend against the horse's back that gives it: that lean plus the saddle's
  pitch (``rearPivot.rz + backMid.rz``: the saddle tilts the rider with the horse), within
  ``max_bend``; ``hip_share`` of it at the hip (a fold from the hip), the rest shared by
  the lower back and the waist; the head counters ``head_follow`` of the lean (eyes ahead, as Eq. 10 does);
- each of ``hip.rz``, ``lower_back.rz``, ``waist.rz``, ``head.rz`` moves from the rules'
  value toward that pose by ``weight * max(rise, hind)``.

Outside a jump (both 0: every gait, a halt, a stop) the rules' values pass unchanged,
bit for bit (tested). The hands need nothing here: the reins part keeps them on the line
to the bit, so as the trunk folds they follow the horse's neck forward (the release).
Angles in degrees, hoof heights in the thesis rig's units (after the length scale), the
rider channels as deltas from the standing rider's (0 for these four, 5 for the head:
:data:`NEUTRAL`). One source for floats and NumPy arrays (``ops`` picks the primitives).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from riderlive.channels import RIDER_INDEX
from riderlive.rules.kuhnel2003 import RULE_INPUTS
from riderlive.rules.params import Jump

FRONT: tuple[int, int] = (RULE_INPUTS.index("lfHoof.ty"), RULE_INPUTS.index("rfHoof.ty"))
BACK: tuple[int, int] = (RULE_INPUTS.index("lbHoof.ty"), RULE_INPUTS.index("rbHoof.ty"))
PITCH = RULE_INPUTS.index("rearPivot.rz")
HEIGHT = RULE_INPUTS.index("rearPivot.ty")
BEND = RULE_INPUTS.index("backMid.rz")
"""Positions among the rules' arguments (thesis units, degrees); the saddle's pitch is their sum."""
OUTPUTS: tuple[int, ...] = tuple(RIDER_INDEX[n] for n in ("hip.rz", "lower_back.rz", "waist.rz", "head.rz"))
"""The rider channels the layer moves, in the order of :func:`pose`'s result."""
NEUTRAL: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 5.0)
"""Those channels for the standing horse (``rider_neutral``: the skeleton's rest), degrees."""
BACK_SHARE = 0.4
"""Of the bend not at the hip, the lower back's share (the waist takes the rest)."""


def _ramp(x: Any, start: float, full: float, clip: Callable[[Any, float, float], Any]) -> Any:
    """Smoothstep of ``x`` from ``start`` (0) to ``full`` (1)."""
    s = clip((x - start) / (full - start), 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def _clip_float(x: float, lo: float, hi: float) -> float:
    return min(max(x, lo), hi)


def activation(p: Jump, pitch: Any, height: Any, front: Any, back: Any) -> tuple[Any, Any]:
    """``(rise, hind)`` for the horse's pitch (``rearPivot.rz``, deg), its hindquarters' height
    (``rearPivot.ty``) and the front and back hooves' height sums (thesis units)."""
    array = isinstance(pitch, np.ndarray)
    clip: Callable[[Any, float, float], Any] = np.clip if array else _clip_float
    pitched = _ramp(pitch, p.pitch_from, p.pitch_full, clip) * (1.0 - _ramp(-height, p.sit_from, p.sit_full, clip))
    lifted = _ramp(front, p.hooves_from, p.hooves_full, clip)
    rise = np.maximum(pitched, lifted) if array else max(pitched, lifted)
    return rise, _ramp(back, p.hooves_from, p.hooves_full, clip)


def lean(p: Jump, rise: Any, hind: Any) -> Any:
    """The trunk's world lean aimed at (deg, + forward of upright)."""
    return p.fold * rise + p.land * (1.0 - rise) * hind


def pose(p: Jump, saddle: Any, rise: Any, hind: Any) -> tuple[Any, Any, Any, Any]:
    """Target ``hip.rz``, ``lower_back.rz``, ``waist.rz``, ``head.rz`` (deg) for the saddle's pitch (deg)."""
    world = lean(p, rise, hind)
    bend = np.clip(world + saddle, -p.max_bend, p.max_bend)
    if not isinstance(bend, np.ndarray):
        bend = float(bend)
    rest = (1.0 - p.hip_share) * bend
    return (
        NEUTRAL[0] + p.hip_share * bend,
        NEUTRAL[1] + BACK_SHARE * rest,
        NEUTRAL[2] + (1.0 - BACK_SHARE) * rest,
        NEUTRAL[3] - p.head_follow * world,
    )


def apply_scalar(p: Jump, args: list[float], out: list[float]) -> None:
    """The layer on one frame: ``args`` the rules' arguments (thesis units), ``out`` their output, changed in place."""
    if p.weight == 0.0:
        return
    pitch = args[PITCH]
    front, back = args[FRONT[0]] + args[FRONT[1]], args[BACK[0]] + args[BACK[1]]
    if pitch <= p.pitch_from and front <= p.hooves_from and back <= p.hooves_from:
        return  # no jump: Appendix B exactly
    rise, hind = activation(p, pitch, args[HEIGHT], front, back)
    w = p.weight * max(rise, hind)
    for column, target in zip(OUTPUTS, pose(p, pitch + args[BEND], rise, hind), strict=True):
        out[column] += w * (target - out[column])


def weights(p: Jump, args: list[Any]) -> Any:
    """(N,) how far the layer moves each frame's trunk and head toward its pose (0: Appendix B's
    values exactly), from the rules' argument columns (thesis units). For tools that model the rules
    alone (a fit): frames with a weight above 0 are not Appendix B's in :data:`OUTPUTS`."""
    pitch = np.asarray(args[PITCH], dtype=np.float64)
    front = np.asarray(args[FRONT[0]] + args[FRONT[1]], dtype=np.float64)
    back = np.asarray(args[BACK[0]] + args[BACK[1]], dtype=np.float64)
    rise, hind = activation(p, pitch, np.asarray(args[HEIGHT], dtype=np.float64), front, back)
    return p.weight * np.maximum(rise, hind)


def apply_columns(p: Jump, args: list[Any], out: Any, gain: Any, offset: Any) -> None:
    """The layer on (N,) argument columns (thesis units) and an (N, len(RIDER)) output already through
    the animator layer (``out = rules * gain + offset``): each moved channel becomes
    ``(rules + w * (target - rules)) * gain + offset``, in place. Frames outside a jump are untouched."""
    if p.weight == 0.0:
        return
    pitch = np.asarray(args[PITCH], dtype=np.float64)
    front = np.asarray(args[FRONT[0]] + args[FRONT[1]], dtype=np.float64)
    back = np.asarray(args[BACK[0]] + args[BACK[1]], dtype=np.float64)
    rows = np.flatnonzero((pitch > p.pitch_from) | (front > p.hooves_from) | (back > p.hooves_from))
    if rows.size == 0:
        return
    pitch, front, back = pitch[rows], front[rows], back[rows]
    rise, hind = activation(p, pitch, np.asarray(args[HEIGHT], dtype=np.float64)[rows], front, back)
    w = p.weight * np.maximum(rise, hind)
    saddle = pitch + np.asarray(args[BEND], dtype=np.float64)[rows]
    for column, target in zip(OUTPUTS, pose(p, saddle, rise, hind), strict=True):
        current = out[rows, column]
        out[rows, column] = current + w * (target * gain[column] + offset[column] - current)
