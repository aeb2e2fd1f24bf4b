"""Bone chains driven by simulated strands (the skin-and-bones tail of the post).

Each bone ``j`` of a chain spans strand vertices ``j`` and ``j+1``; its long axis is
the rig's twist axis, local +x (the rigs rotate X to twist). A bone's frame is its
axis plus a unit "up" vector ``y`` perpendicular to it (z = x cross y). Layout is
``(B, 3, C)``: bone, coordinate, chain, like the strands.

Per step (:func:`step`):

1. Shortest-arc alignment: each bone's frame is rotated by the smallest rotation
   taking its old axis to its strand segment's new direction (``y`` is carried
   along by that rotation, which has no component about the axis).
2. Torsion springs: at each joint the child's twist relative to its parent (the
   parent's frame carried onto the child's axis by the shortest arc) decays at
   ``twist_rate``; the correction is shared half and half between the two bones,
   so a twist spreads up and down the chain until it is uniform (a joint folded back
   beyond ~148 degrees has no well-defined relative twist and rests). Bone 0 is rigid
   with the anchor (the dock, the head), which gives the chain its twist input.
3. Torsional velocity: the twist each bone turned by this step, over ``dt``.
4. Fan-out: for chains that have them, sub-chains on the lower half sit at a distance
   from the centre bone that follows ``fan_gain * |torsional velocity| * profile``
   (profile rising from 0 at mid-chain to 1 at the tip) with time constant
   ``fan_time``, limited to ``fan_max``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
FOLDED = -0.85
"""Cosine of the joint angle (about 148 degrees) beyond which a torsion spring rests."""


@dataclass(frozen=True, eq=False)
class ChainModel:
    """Static parameters of ``C`` chains of ``B`` bones; ``fan_profile`` is (B, C), 0 where no fan."""

    dt: float
    twist_rate: float
    fan_gain: float
    fan_max: float
    fan_time: float
    fan_profile: FloatArray

    @property
    def twist_share(self) -> float:
        """Fraction of a joint's relative twist removed per step."""
        return float(1.0 - np.exp(-self.twist_rate * self.dt))

    @property
    def fan_share(self) -> float:
        return float(1.0 - np.exp(-self.dt / self.fan_time))


@dataclass(frozen=True, eq=False)
class ChainState:
    """Bone axes and up vectors (B, 3, C), torsional velocity (B, C) rad/s, fan distance (B, C) m."""

    axis: FloatArray
    up: FloatArray
    twist_velocity: FloatArray
    fan: FloatArray


def fan_profile(bones: int, chains_with_fan: list[bool]) -> FloatArray:
    """0 on the upper half, rising linearly to 1 at the tip bone, for the chains that fan out."""
    start = bones // 2
    ramp = np.clip((np.arange(bones) - start + 1) / max(bones - start, 1), 0.0, 1.0)
    return np.stack([ramp if fan else np.zeros(bones) for fan in chains_with_fan], axis=1)


_ONES3 = np.ones(3)


def _dot(a: FloatArray, b: FloatArray) -> FloatArray:
    """Dot product over axis 1 of (B, 3, C) arrays."""
    out: FloatArray = _ONES3 @ (a * b)
    return out


def _cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """Cross product over axis 1 of (B, 3, C) arrays."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


def carry(a: FloatArray, b: FloatArray, v: FloatArray) -> FloatArray:
    """Rotate ``v`` (perpendicular to ``a``) by the shortest arc taking unit ``a`` to unit ``b`` (all (B, 3, C)).

    For ``v`` perpendicular to ``a`` that rotation reduces to
    ``v - (v.b) / (1 + a.b) (a + b)`` (two reflections: across the plane normal to
    ``a + b``, then across the one normal to ``b``). ``a`` and ``b`` must not be
    opposite (one step never turns a bone by 180 degrees).
    """
    scale = _dot(v, b) / np.maximum(1.0 + _dot(a, b), 1e-12)
    out: FloatArray = v - scale[:, None, :] * (a + b)
    return out


def directions(x: FloatArray) -> FloatArray:
    """Unit segment directions (B, 3, C) of strand vertices (B+1, 3, C)."""
    d = x[1:] - x[:-1]
    d /= np.sqrt(np.maximum(_dot(d, d), 1e-24))[:, None, :]
    return d


def _perpendicular_unit(up: FloatArray, axis: FloatArray) -> FloatArray:
    up = up - _dot(up, axis)[:, None, :] * axis
    up /= np.sqrt(_dot(up, up))[:, None, :]
    return up


def rest_state(x: FloatArray, anchor_up: FloatArray) -> ChainState:
    """Bone frames for strand vertices ``x``: bone 0's up is ``anchor_up`` (3, C), carried down the chain."""
    axis = directions(x)
    up = np.empty_like(axis)
    up[0] = _perpendicular_unit(anchor_up[None], axis[:1])[0]
    for j in range(1, axis.shape[0]):
        up[j] = _perpendicular_unit(carry(axis[j - 1 : j], axis[j : j + 1], up[j - 1 : j]), axis[j : j + 1])[0]
    zeros = np.zeros(axis[:, 0].shape)
    return ChainState(axis, up, zeros, zeros.copy())


def step(model: ChainModel, state: ChainState, x: FloatArray, anchor_up: FloatArray) -> ChainState:
    """Follow the strands' new vertices ``x`` (B+1, 3, C); ``anchor_up`` (3, C) is bone 0's up now."""
    axis = directions(x)
    carried = carry(state.axis, axis, state.up)
    up = carried.copy()
    up[0] = anchor_up
    up = _perpendicular_unit(up, axis)
    side = _cross(axis, up)
    turned = np.zeros(axis[:, 0].shape)
    # Bone 0 turns with its anchor: the angle from its carried frame to the anchor's.
    turned[0] = np.arctan2(-_dot(carried[:1], side[:1]), _dot(carried[:1], up[:1]))[0]
    if axis.shape[0] > 1:
        # Torsion springs between neighbours (Jacobi: every joint from the same frames).
        ref = carry(axis[:-1], axis[1:], up[:-1])
        share = np.arctan2(-_dot(ref, side[1:]), _dot(ref, up[1:]))
        share *= model.twist_share
        share[_dot(axis[:-1], axis[1:]) < FOLDED] = 0.0  # a joint folded back on itself has no defined twist
        turn = np.zeros(turned.shape)
        turn[1:] -= 0.5 * share  # each child turns back by half its joint's correction...
        turn[1] -= 0.5 * share[0]  # ...bone 1 by all of it, as bone 0 is rigid with the anchor
        turn[1:-1] += 0.5 * share[1:]  # each parent turns forward by the other half
        up = up * np.cos(turn)[:, None, :] + side * np.sin(turn)[:, None, :]
        turned += turn
    velocity = turned / model.dt
    target = np.minimum(model.fan_gain * np.abs(velocity) * model.fan_profile, model.fan_max)
    fan = state.fan + model.fan_share * (target - state.fan)
    return ChainState(axis, up, velocity, fan)


def subchain_positions(state: ChainState, x: FloatArray, count: int) -> FloatArray:
    """World positions (count, B, 3, C) of the fan-out sub-chains' bones, evenly spread about each centre bone."""
    side = _cross(state.axis, state.up)
    angles = 2.0 * np.pi * np.arange(count) / max(count, 1)
    radial = np.cos(angles)[:, None, None, None] * state.up[None] + np.sin(angles)[:, None, None, None] * side[None]
    return np.asarray(x[None, :-1] + state.fan[None, :, None, :] * radial, dtype=np.float64)


def world_rotations(state: ChainState) -> FloatArray:
    """Bone world rotation matrices (B, C, 3, 3): columns are the bone's x (axis), y (up), z."""
    side = _cross(state.axis, state.up)
    return np.stack((state.axis.transpose(0, 2, 1), state.up.transpose(0, 2, 1), side.transpose(0, 2, 1)), axis=-1)
