"""Bone chains driven by simulated strands (the skin-and-bones tail of the post), compiled.

Each bone ``j`` of a chain spans strand vertices ``j`` and ``j+1``; its long axis is
the rig's twist axis, local +x (the rigs rotate X to twist). A bone's frame is its
axis plus a unit "up" vector ``y`` perpendicular to it (z = x cross y). Layout is
``(B, 3, C)``: bone, coordinate, chain, like the strands. The kernels loop one chain
(column) at a time, bone by bone; written once and compiled (:mod:`riderlive.fastpath`).

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

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from riderlive.fastpath import inline, kernel
from riderlive.physics.vec3 import Vec, at, cross, divided, dot, fmax, put, scaled, sub

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

    @property
    def solver(self) -> tuple[FloatArray, float, float, float, float, float]:
        """The arguments :func:`follow` takes after the state, the strand vertices and the anchors' up."""
        profile = np.ascontiguousarray(self.fan_profile, dtype=np.float64)
        return (profile, float(self.dt), self.twist_share, self.fan_share, float(self.fan_gain), float(self.fan_max))


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


def rest_state(x: FloatArray, anchor_up: FloatArray) -> ChainState:
    """Bone frames for strand vertices ``x`` (B+1, 3, C); bone 0's up is ``anchor_up`` (3, C), carried down."""
    axis, up = rest_frames(np.ascontiguousarray(x), np.ascontiguousarray(anchor_up))
    zeros = np.zeros(axis[:, 0].shape)
    return ChainState(axis, up, zeros, zeros.copy())


def step(model: ChainModel, state: ChainState, x: FloatArray, anchor_up: FloatArray) -> ChainState:
    """Follow the strands' new vertices ``x`` (B+1, 3, C); ``anchor_up`` (3, C) is bone 0's up now."""
    axis, up, velocity, fan = follow(state.axis, state.up, state.fan, x, anchor_up, *model.solver)
    return ChainState(axis, up, velocity, fan)


def subchain_positions(state: ChainState, x: FloatArray, count: int) -> FloatArray:
    """World positions (count, B, 3, C) of the fan-out sub-chains' bones, evenly spread about each centre bone."""
    side = np.cross(state.axis, state.up, axis=1)
    angles = 2.0 * np.pi * np.arange(count) / max(count, 1)
    radial = np.cos(angles)[:, None, None, None] * state.up[None] + np.sin(angles)[:, None, None, None] * side[None]
    return np.asarray(x[None, :-1] + state.fan[None, :, None, :] * radial, dtype=np.float64)


def world_rotations(state: ChainState) -> FloatArray:
    """Bone world rotation matrices (B, C, 3, 3): columns are the bone's x (axis), y (up), z."""
    side = np.cross(state.axis, state.up, axis=1)
    return np.stack((state.axis.transpose(0, 2, 1), state.up.transpose(0, 2, 1), side.transpose(0, 2, 1)), axis=-1)


# ----------------------------------------------------------------------------- the kernels


@inline
def carry(a: Vec, b: Vec, v: Vec) -> Vec:
    """Rotate ``v`` (perpendicular to unit ``a``) by the shortest arc taking ``a`` to unit ``b``.

    For ``v`` perpendicular to ``a`` that rotation reduces to
    ``v - (v.b) / (1 + a.b) (a + b)`` (two reflections: across the plane normal to
    ``a + b``, then across the one normal to ``b``). ``a`` and ``b`` must not be
    opposite (one step never turns a bone by 180 degrees).
    """
    k = dot(v, b) / fmax(1.0 + dot(a, b), 1e-12)
    return (v[0] - k * (a[0] + b[0]), v[1] - k * (a[1] + b[1]), v[2] - k * (a[2] + b[2]))


@inline
def direction(x: FloatArray, j: int, ch: int) -> Vec:
    """The unit direction of segment ``j`` of chain ``ch``'s vertices."""
    d = sub(at(x, j + 1, ch), at(x, j, ch))
    return divided(d, math.sqrt(fmax(dot(d, d), 1e-24)))


@inline
def perpendicular_unit(v: Vec, a: Vec) -> Vec:
    """``v`` less its component along unit ``a``, normalised."""
    u = sub(v, scaled(a, dot(v, a)))
    return divided(u, math.sqrt(dot(u, u)))


@kernel
def rest_frames(x: FloatArray, anchor_up: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Axes and up vectors (B, 3, C) of bones along vertices ``x``, bone 0's up from ``anchor_up`` (3, C)."""
    n_bones, n = x.shape[0] - 1, x.shape[2]
    axis, up = np.empty((n_bones, 3, n)), np.empty((n_bones, 3, n))
    for ch in range(n):
        u = (anchor_up[0, ch], anchor_up[1, ch], anchor_up[2, ch])
        previous = direction(x, 0, ch)
        for j in range(n_bones):
            a = direction(x, j, ch)
            u = perpendicular_unit(u if j == 0 else carry(previous, a, u), a)
            put(axis, j, ch, a)
            put(up, j, ch, u)
            previous = a
    return axis, up


@kernel
def follow(  # noqa: PLR0917
    old_axis: FloatArray,
    old_up: FloatArray,
    old_fan: FloatArray,
    x: FloatArray,
    anchor_up: FloatArray,
    fan_profile: FloatArray,
    dt: float,
    twist_share: float,
    fan_share: float,
    fan_gain: float,
    fan_max: float,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """One step of every chain: axes, up vectors, torsional velocities, fan distances.

    1. Each bone's frame follows its segment by the shortest arc; bone 0's up is the anchor's.
    2. Torsion springs (Jacobi: every joint from the same frames): the child's twist
       relative to its parent decays by ``twist_share``, half turned back on the
       child, half forward on the parent (all of it on bone 1: bone 0 is rigid with
       the anchor); a joint folded beyond :data:`FOLDED` rests.
    3. Torsional velocity: each bone's turn this step over ``dt`` (bone 0: the turn
       from its carried frame to the anchor's).
    4. Fan-out: the sub-chains' distance follows ``fan_gain |velocity| profile`` (at most
       ``fan_max``) by ``fan_share`` per step.
    """
    n_bones, _, n = old_axis.shape
    axis, up, side = np.empty_like(old_axis), np.empty_like(old_up), np.empty_like(old_up)
    velocity, fan = np.empty_like(old_fan), np.empty_like(old_fan)
    turn, share = np.zeros(n_bones), np.zeros(n_bones)
    for ch in range(n):
        carried0 = (0.0, 0.0, 0.0)
        for j in range(n_bones):
            a = direction(x, j, ch)
            carried = carry(at(old_axis, j, ch), a, at(old_up, j, ch))
            if j == 0:
                carried0 = carried
                carried = (anchor_up[0, ch], anchor_up[1, ch], anchor_up[2, ch])
            u = perpendicular_unit(carried, a)
            put(axis, j, ch, a)
            put(up, j, ch, u)
            put(side, j, ch, cross(a, u))
        turned0 = math.atan2(-dot(carried0, at(side, 0, ch)), dot(carried0, at(up, 0, ch)))
        for j in range(n_bones):
            turn[j] = 0.0
        if n_bones > 1:
            for j in range(n_bones - 1):
                ref = carry(at(axis, j, ch), at(axis, j + 1, ch), at(up, j, ch))
                share[j] = math.atan2(-dot(ref, at(side, j + 1, ch)), dot(ref, at(up, j + 1, ch))) * twist_share
                if dot(at(axis, j, ch), at(axis, j + 1, ch)) < FOLDED:
                    share[j] = 0.0
            for j in range(1, n_bones):
                turn[j] -= 0.5 * share[j - 1]
            turn[1] -= 0.5 * share[0]
            for j in range(1, n_bones - 1):
                turn[j] += 0.5 * share[j]
            for j in range(n_bones):
                cs, sn = math.cos(turn[j]), math.sin(turn[j])
                for c in range(3):
                    up[j, c, ch] = up[j, c, ch] * cs + side[j, c, ch] * sn
        for j in range(n_bones):
            velocity[j, ch] = ((turned0 if j == 0 else 0.0) + turn[j]) / dt
            target = min(fan_gain * abs(velocity[j, ch]) * fan_profile[j, ch], fan_max)
            fan[j, ch] = old_fan[j, ch] + fan_share * (target - old_fan[j, ch])
    return axis, up, velocity, fan
