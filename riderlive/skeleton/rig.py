"""Skeletons and rigs as data, and the pure solver that poses a skeleton from channels.

Axis convention (every skeleton here): metres, right-handed, ``+x`` forward, ``+y`` up,
``+z`` to the character's right (so left bones have ``z < 0``). This is the thesis rigs'
translate convention (X forward/back, Y up/down, Z side to side). Every bone's rest
orientation is the identity, aligned with these axes; a bone's ``offset`` is its
joint's position in its parent's frame. A pose gives each bone a local rotation
relative to its rest orientation, as a quaternion ``(x, y, z, w)``, and a local
translation (the offset, moved by translation channels).

A rig drives a skeleton from named channels, all taken as deltas from the rig's
``neutral`` values, so the neutral values give the rest pose (identity rotations):

- ``rotations``: channel -> rotation of a bone about a fixed axis (degrees, sign);
  entries on one bone compose in list order (each later one applied after).
- ``translations``: channel -> offset of a bone along an axis (metres, sign).
- ``chains``: two-bone IK. The end joint's target and the middle joint's pole are
  rest positions in the frame of ``frame`` (a bone, or ``None`` = skeleton origin)
  moved by channels; the end bone's world orientation is that frame's, turned by
  its own rotation entries.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from riderlive.skeleton import quat
from riderlive.skeleton.quat import IDENTITY, SCALAR, Ops, Quat, Vec3

AXES: dict[str, str] = {
    "units": "m",
    "handedness": "right",
    "forward": "+x",
    "up": "+y",
    "right": "+z",
    "quaternion": "x, y, z, w; local, relative to the bone's rest orientation (identity)",
    "rest": "every bone's rest orientation is the identity; offset = joint position in the parent's frame",
}
"""The axis convention of every skeleton, as published in the hello."""

X: Vec3 = (1.0, 0.0, 0.0)
Y: Vec3 = (0.0, 1.0, 0.0)
Z: Vec3 = (0.0, 0.0, 1.0)
_AXIS_NAMES: dict[Vec3, str] = {X: "x", Y: "y", Z: "z"}


@dataclass(frozen=True, slots=True)
class Bone:
    name: str
    parent: int
    """Index of the parent bone (always smaller than this bone's), -1 for the root."""
    offset: Vec3
    """Rest position of the joint in the parent's frame, metres."""


def bones_from_rows(rows: Sequence[tuple[str, str | None, Vec3]]) -> tuple[Bone, ...]:
    """Bones from ``(name, parent name or None, offset)`` rows listed parents first."""
    index: dict[str, int] = {}
    bones: list[Bone] = []
    for name, parent, offset in rows:
        bones.append(Bone(name, -1 if parent is None else index[parent], offset))
        index[name] = len(bones) - 1
    return tuple(bones)


@dataclass(frozen=True, slots=True)
class Drive:
    """One channel moving one degree of freedom: ``sign * (value - neutral)`` along/about ``axis``."""

    channel: str
    bone: str
    axis: Vec3
    sign: float = 1.0


@dataclass(frozen=True, slots=True)
class Offset:
    """One channel moving an IK target or pole point along ``axis``."""

    channel: str
    axis: Vec3
    sign: float = 1.0


@dataclass(frozen=True, slots=True)
class Chain:
    """Two-bone IK: ``upper`` -> ``lower`` -> ``end`` joints."""

    upper: str
    lower: str
    end: str
    frame: str | None
    target: tuple[Offset, ...] = ()
    pole: tuple[Offset, ...] = ()


@dataclass(frozen=True)
class Rig:
    """A skeleton and how channels drive it (see the module docstring)."""

    name: str
    bones: tuple[Bone, ...]
    neutral: Mapping[str, float]
    rotations: tuple[Drive, ...] = ()
    translations: tuple[Drive, ...] = ()
    chains: tuple[Chain, ...] = ()
    index: dict[str, int] = field(init=False)
    subtree: tuple[tuple[int, ...], ...] = field(init=False)
    """Per bone: itself and its descendants, parents first."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "index", {b.name: i for i, b in enumerate(self.bones)})
        below: list[list[int]] = [[i] for i in range(len(self.bones))]
        for i in range(len(self.bones) - 1, -1, -1):
            p = self.bones[i].parent
            if p >= 0:
                below[p] = [p, *sorted(set(below[p][1:]) | set(below[i]))]
        for i, b in enumerate(self.bones):
            if not -1 <= b.parent < i:
                raise ValueError(f"{self.name}: bone {b.name!r} has parent {b.parent}; parents must come first")
        for d in (*self.rotations, *self.translations):
            if d.bone not in self.index:
                raise ValueError(f"{self.name}: drive of {d.channel!r} names unknown bone {d.bone!r}")
        for c in self.chains:
            u, lo, e = (self.index[n] for n in (c.upper, c.lower, c.end))
            if self.bones[lo].parent != u or self.bones[e].parent != lo:
                raise ValueError(f"{self.name}: chain {c.upper}->{c.lower}->{c.end} is not a parent chain")
        object.__setattr__(self, "subtree", tuple(tuple(b) for b in below))
        rest: list[Vec3] = []
        for b in self.bones:
            rest.append(b.offset if b.parent < 0 else quat.add(rest[b.parent], b.offset))
        object.__setattr__(self, "_rest", tuple(rest))

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(b.name for b in self.bones)

    def rest_world(self) -> list[Vec3]:
        """Rest joint positions in the skeleton frame, metres."""
        return list(self._rest)  # type: ignore[attr-defined]

    def to_json(self) -> dict[str, Any]:
        """The rig as JSON-ready data (what the hello and the page use)."""
        rest = self.rest_world()

        def frame_pos(frame: str | None) -> Vec3:
            return (0.0, 0.0, 0.0) if frame is None else rest[self.index[frame]]

        def offsets(items: tuple[Offset, ...]) -> list[dict[str, Any]]:
            return [{"channel": o.channel, "axis": _AXIS_NAMES[o.axis], "sign": o.sign} for o in items]

        return {
            "bones": [{"name": b.name, "parent": b.parent, "offset": list(b.offset)} for b in self.bones],
            "neutral": dict(self.neutral),
            "rotations": [
                {"channel": d.channel, "bone": d.bone, "axis": _AXIS_NAMES[d.axis], "sign": d.sign}
                for d in self.rotations
            ],
            "translations": [
                {"channel": d.channel, "bone": d.bone, "axis": _AXIS_NAMES[d.axis], "sign": d.sign}
                for d in self.translations
            ],
            "chains": [
                {
                    "upper": c.upper,
                    "lower": c.lower,
                    "end": c.end,
                    "frame": c.frame,
                    "target_rest": list(quat.sub(rest[self.index[c.end]], frame_pos(c.frame))),
                    "pole_rest": list(quat.sub(rest[self.index[c.lower]], frame_pos(c.frame))),
                    "target": offsets(c.target),
                    "pole": offsets(c.pole),
                }
                for c in self.chains
            ],
        }


@dataclass(frozen=True, slots=True)
class Pose:
    """A posed skeleton: local and world transforms per bone, in the rig's bone order."""

    local_rotations: list[Quat]
    local_offsets: list[Vec3]
    world_rotations: list[Quat]
    world_positions: list[Vec3]


def _forward(
    rig: Rig,
    local_rot: list[Quat],
    local_off: list[Vec3],
    wrot: list[Quat],
    wpos: list[Vec3],
    *,
    bones: Iterable[int],
) -> None:
    """World transforms of ``bones`` (parents first) from local ones, in place."""
    for i in bones:
        p = rig.bones[i].parent
        if p < 0:
            wrot[i], wpos[i] = local_rot[i], local_off[i]
        else:
            pr = wrot[p]
            wrot[i] = quat.mul(pr, local_rot[i])
            wpos[i] = quat.add(wpos[p], quat.rotate(pr, local_off[i]))


def _any_perpendicular(u: Vec3, ops: Ops) -> Vec3:
    other = quat.choose(abs(u[0]) < 0.9, X, Y, ops)
    return quat.unit(quat.cross(u, other), ops)


def solve(rig: Rig, values: Mapping[str, Any], ops: Ops = SCALAR) -> Pose:
    """Pose ``rig`` from channel ``values`` (missing channels stay at neutral).

    Pure: no state, no I/O. Rotations in degrees, lengths in metres. ``values`` are
    floats (one frame; ``ops`` = ``quat.SCALAR``) or equal-length NumPy arrays (N
    frames at once; ``ops`` = ``quat.ARRAY``, see :func:`solve_frames`); the same
    source poses both.
    """
    neutral = rig.neutral

    def delta(channel: str) -> Any:
        v = values.get(channel)
        if v is None:
            return 0.0
        if ops is SCALAR:
            return v - neutral.get(channel, 0.0) if math.isfinite(v) else 0.0
        return ops.where(ops.isfinite(v), v - neutral.get(channel, 0.0), 0.0)

    n = len(rig.bones)
    local_rot: list[Quat] = [IDENTITY] * n
    local_off: list[Vec3] = [b.offset for b in rig.bones]
    for d in rig.rotations:
        i = rig.index[d.bone]
        local_rot[i] = quat.mul(quat.from_axis_angle(d.axis, d.sign * delta(d.channel), ops), local_rot[i])
    for d in rig.translations:
        i = rig.index[d.bone]
        local_off[i] = quat.add(local_off[i], quat.scale(d.axis, d.sign * delta(d.channel)))
    end_turn = {rig.index[c.end]: local_rot[rig.index[c.end]] for c in rig.chains}
    wrot: list[Quat] = [IDENTITY] * n
    wpos: list[Vec3] = [(0.0, 0.0, 0.0)] * n
    _forward(rig, local_rot, local_off, wrot, wpos, bones=range(n))
    rest = rig.rest_world()

    for c in rig.chains:
        iu, il, ie = rig.index[c.upper], rig.index[c.lower], rig.index[c.end]
        if c.frame is None:
            frot, fpos, frest = IDENTITY, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
        else:
            fi = rig.index[c.frame]
            frot, fpos, frest = wrot[fi], wpos[fi], rest[fi]
        target_local = quat.sub(rest[ie], frest)
        for o in c.target:
            target_local = quat.add(target_local, quat.scale(o.axis, o.sign * delta(o.channel)))
        pole_local = quat.sub(rest[il], frest)
        for o in c.pole:
            pole_local = quat.add(pole_local, quat.scale(o.axis, o.sign * delta(o.channel)))
        target = quat.add(fpos, quat.rotate(frot, target_local))
        pole = quat.add(fpos, quat.rotate(frot, pole_local))

        a = wpos[iu]
        l1 = quat.norm(local_off[il], ops)
        l2 = quat.norm(local_off[ie], ops)
        to_t = quat.sub(target, a)
        dist = quat.norm(to_t, ops)
        u = quat.choose(dist > 1e-12, quat.unit(to_t, ops), _any_perpendicular(quat.unit(pole, ops), ops), ops)
        c_len = ops.minimum(ops.maximum(dist, abs(l1 - l2) + 1e-9), l1 + l2 - 1e-9)
        cos_a = (l1 * l1 + c_len * c_len - l2 * l2) / (2.0 * l1 * c_len)
        sin_a = ops.sqrt(ops.maximum(0.0, 1.0 - cos_a * cos_a))
        to_p = quat.sub(pole, a)
        v = quat.sub(to_p, quat.scale(u, quat.dot(to_p, u)))
        v = quat.choose(quat.norm(v, ops) > 1e-12, quat.unit(v, ops), _any_perpendicular(u, ops), ops)
        elbow = quat.add(a, quat.add(quat.scale(u, l1 * cos_a), quat.scale(v, l1 * sin_a)))
        end = quat.add(a, quat.scale(u, c_len))

        d0u, d0l = quat.unit(local_off[il], ops), quat.unit(local_off[ie], ops)
        n0 = quat.unit(quat.cross(d0u, d0l), ops)
        d1u, d1l = quat.unit(quat.sub(elbow, a), ops), quat.unit(quat.sub(end, elbow), ops)
        n1 = quat.unit(quat.cross(d1u, d1l), ops)
        upper_world = quat.frame_rotation(d0u, n0, d1u, n1, ops)
        lower_world = quat.frame_rotation(d0l, n0, d1l, n1, ops)
        parent_u = rig.bones[iu].parent
        parent_rot = wrot[parent_u] if parent_u >= 0 else IDENTITY
        local_rot[iu] = quat.mul(quat.conj(parent_rot), upper_world)
        local_rot[il] = quat.mul(quat.conj(upper_world), lower_world)
        local_rot[ie] = quat.mul(quat.conj(lower_world), quat.mul(frot, end_turn[ie]))
        _forward(rig, local_rot, local_off, wrot, wpos, bones=rig.subtree[iu])

    return Pose(
        local_rotations=[quat.normalize(q, ops) for q in local_rot],
        local_offsets=local_off,
        world_rotations=wrot,
        world_positions=wpos,
    )


@dataclass(frozen=True, slots=True)
class PoseArrays:
    """N poses as arrays, bone-major (one bone's track is contiguous): rotations (B, N, 4) x y z w,
    positions and offsets (B, N, 3) metres, in the rig's bone order."""

    local_rotations: npt.NDArray[np.float64]
    local_offsets: npt.NDArray[np.float64]
    world_rotations: npt.NDArray[np.float64]
    world_positions: npt.NDArray[np.float64]


def _stack(items: Sequence[Sequence[Any]], frames: int) -> npt.NDArray[np.float64]:
    """Per-bone tuples of components (floats or (N,) arrays) -> (bones, N, components)."""
    out = np.empty((len(items), len(items[0]), frames), dtype=np.float64)
    for b, item in enumerate(items):
        for k, component in enumerate(item):
            out[b, k] = component
    return np.ascontiguousarray(out.transpose(0, 2, 1))


def solve_frames(rig: Rig, columns: Mapping[str, npt.NDArray[np.float64]], frames: int) -> PoseArrays:
    """:func:`solve` on N frames at once: ``columns`` maps channels to (N,) arrays."""
    pose = solve(rig, columns, quat.ARRAY)
    return PoseArrays(
        _stack(pose.local_rotations, frames),
        _stack(pose.local_offsets, frames),
        _stack(pose.world_rotations, frames),
        _stack(pose.world_positions, frames),
    )
