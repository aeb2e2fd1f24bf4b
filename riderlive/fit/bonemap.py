"""A rider from mocap: BVH joints mapped onto the rider skeleton and read back as rider channels.

A bone map (``config/bonemaps/NAME.toml``, ``docs/skeleton.md``) names, for each bone of the
rider skeleton (:func:`riderlive.skeleton.rider_rig`), the BVH joint that plays it, the
joint whose frame is the seat (the rider's root; absent: the world), the file's length unit
and its axes (which signed file axis points forward, up and to the rider's right; a
left-handed file, such as Unity's, converts too). The file's rest pose (all channels 0) is
taken as the rider's neutral pose, so every channel reads ``neutral + change from rest``.

The rig is inverted from its own data, not rewritten: each rotation drive's bone gets its
rotation relative to its parent's mapped joint (the IK chains' end bones: relative to the
seat, as the rig turns them) and the drives on it are read back as Euler angles in the
rig's order; translation drives read the joint's local position; the IK targets (wrists,
feet) read the end joint's position in the seat frame less the offsets of channels already
read (the seat's ``cog.*``); where the limb is straight the IK may have stopped short of its
target, so those frames read as missing (NaN, left out of the fit and counted). Not readable
from a pose, so never in a BVH rider: the knee and elbow poles (only their plane shows),
hair and cloth attributes.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Literal

import numpy as np
import numpy.typing as npt
import pydantic

from riderlive.channels import RIDER_INDEX, RIDER_NAMES, Kind, lookup
from riderlive.configfile import CONFIG_DIR, StrictModel, load
from riderlive.fit.bvh import BvhTake, read_bvh
from riderlive.fit.problem import FitInputError, RiderTake
from riderlive.fit.takes import sha256
from riderlive.frameunits import METRES
from riderlive.names import check_name
from riderlive.skeleton import rider_rig
from riderlive.skeleton.rig import Chain, Rig

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

BONEMAP_DIR = CONFIG_DIR / "bonemaps"
DEFAULT_BONEMAP = "riderlive"
UNITS: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254}
"""Metres per file length unit."""
_AXES = {"+x": (0, 1.0), "-x": (0, -1.0), "+y": (1, 1.0), "-y": (1, -1.0), "+z": (2, 1.0), "-z": (2, -1.0)}
AxisName = Literal["+x", "-x", "+y", "-y", "+z", "-z"]


class Axes(StrictModel):
    """The file axis along the rider's forward (+x), up (+y) and right (+z)."""

    forward: AxisName
    up: AxisName
    right: AxisName

    @pydantic.model_validator(mode="after")
    def _distinct(self) -> Axes:
        if len({self.forward[1], self.up[1], self.right[1]}) != 3:
            raise ValueError("forward, up and right must be three different file axes")
        return self

    def matrix(self) -> FloatArray:
        """Rider-from-file: ``rider = A @ file`` (a signed permutation)."""
        a = np.zeros((3, 3))
        for row, name in enumerate((self.forward, self.up, self.right)):
            axis, sign = _AXES[name]
            a[row, axis] = sign
        return a


class BoneMap(StrictModel):
    """A bone map file (see the module docstring)."""

    name: str
    description: str = ""
    unit: Literal["m", "cm", "mm", "in"] = "m"
    axes: Axes
    seat: str | None = None  # the joint whose frame is the rider's root (the seat point), None: the world
    joints: dict[str, str]  # rider bone -> BVH joint
    read: list[str] | None = None  # the rider channels to read (None: every one the pose determines)

    @pydantic.field_validator("read")
    @classmethod
    def _known_channels(cls, read: list[str] | None) -> list[str] | None:
        unknown = sorted(set(read or ()) - set(RIDER_NAMES))
        if unknown:
            raise ValueError(f"not rider channels: {', '.join(unknown)}")
        return read

    @pydantic.field_validator("joints")
    @classmethod
    def _known_bones(cls, joints: dict[str, str]) -> dict[str, str]:
        unknown = sorted(set(joints) - set(rider_rig().names))
        if unknown:
            raise ValueError(f"not rider bones: {', '.join(unknown)} (bones: docs/skeleton.md)")
        return joints


def load_bonemap(name_or_path: str | None) -> BoneMap:
    """A bone map by shipped name (``config/bonemaps``) or path; None: riderlive's own export."""
    name = name_or_path or DEFAULT_BONEMAP
    path = Path(name) if name.endswith(".toml") else BONEMAP_DIR / f"{check_name(name, 'bone map')}.toml"
    return load(BoneMap, path)


def shipped_bonemaps() -> list[str]:
    return sorted(p.stem for p in BONEMAP_DIR.glob("*.toml"))


# ----------------------------------------------------------------------------- world transforms


def _world(take: BvhTake, axes: FloatArray, to_m: float) -> tuple[FloatArray, FloatArray]:
    """(J, N, 3, 3) world rotations and (J, N, 3) world positions, rider axes, metres."""
    rot, pos = np.empty_like(take.rotations), np.empty_like(take.positions)
    local_rot = axes @ take.rotations @ axes.T
    local_pos = take.positions @ axes.T * to_m
    for k, joint in enumerate(take.joints):
        if joint.parent < 0:
            rot[k], pos[k] = local_rot[k], local_pos[k]
        else:
            p = joint.parent
            rot[k] = rot[p] @ local_rot[k]
            pos[k] = pos[p] + np.einsum("nij,nj->ni", rot[p], local_pos[k])
    return rot, pos


def _rest(take: BvhTake) -> BvhTake:
    """``take``'s rest pose (every channel 0: offsets, identity rotations) as a one-frame take."""
    n = len(take.joints)
    positions = np.array([j.offset for j in take.joints])[:, None, :]
    return BvhTake(take.joints, take.frame_time, np.tile(np.eye(3), (n, 1, 1, 1)), positions)


def _relative(rot: FloatArray, pos: FloatArray, frame: int | None, k: int) -> tuple[FloatArray, FloatArray]:
    """Joint ``k``'s rotation and position in joint ``frame``'s frame (None: the world)."""
    if frame is None:
        return rot[k], pos[k]
    inverse = np.swapaxes(rot[frame], -1, -2)
    return inverse @ rot[k], np.einsum("nij,nj->ni", inverse, pos[k] - pos[frame])


def euler(m: FloatArray, order: tuple[int, int, int]) -> FloatArray:
    """Angles (N, 3) degrees, about axes ``order = (i, j, k)``, of ``m = R_k R_j R_i`` (N, 3, 3)."""
    i, j, k = order
    e = 1.0 if (j - i) % 3 == 1 else -1.0  # (x, y, z) and its rotations: +1
    beta = np.arcsin(np.clip(-e * m[:, k, i], -1.0, 1.0))
    alpha = np.arctan2(e * m[:, k, j], m[:, k, k])
    gamma = np.arctan2(e * m[:, j, i], m[:, i, i])
    out: FloatArray = np.degrees(np.column_stack([alpha, beta, gamma]))
    return out


def _order(axes: list[int]) -> tuple[int, int, int]:
    """A Tait-Bryan order holding ``axes`` (1-3 distinct, first applied first) in their order."""
    if len(axes) == 3:
        return axes[0], axes[1], axes[2]
    missing = [a for a in range(3) if a not in axes]
    if len(axes) == 2:
        return axes[0], missing[0], axes[1]
    return axes[0], missing[0], missing[1]


# ----------------------------------------------------------------------------- the rig, inverted

REACH_TOLERANCE = 1e-6
"""Relative distance from a limb's full length (or its folded length) at which its target may lie beyond."""


def _at_full_reach(chain: Chain, joint: Mapping[str, int], pos: FloatArray, rest_pos: FloatArray) -> BoolArray:
    """Frames where ``chain``'s limb is straight (or folded): the IK stopped short, so its end does not show
    the target (those frames read as missing)."""
    if not {chain.upper, chain.lower, chain.end} <= set(joint):
        return np.zeros(pos.shape[1], dtype=bool)
    u, lo, e = joint[chain.upper], joint[chain.lower], joint[chain.end]
    l1 = float(np.linalg.norm(rest_pos[lo, 0] - rest_pos[u, 0]))
    l2 = float(np.linalg.norm(rest_pos[e, 0] - rest_pos[lo, 0]))
    dist = np.linalg.norm(pos[e] - pos[u], axis=1)
    tolerance = REACH_TOLERANCE * (l1 + l2)
    return np.asarray((dist >= l1 + l2 - tolerance) | (dist <= abs(l1 - l2) + tolerance))


def rider_channels(
    take: BvhTake, bonemap: BoneMap, source: str = "BVH", rig: Rig | None = None
) -> dict[str, FloatArray]:
    """The rider channels (metres, degrees) the pose of every frame of ``take`` determines."""
    rig = rig or rider_rig()
    index = {name: k for k, name in enumerate(take.names)}
    wanted = [*bonemap.joints.values(), *([bonemap.seat] if bonemap.seat else [])]
    missing = sorted({j for j in wanted if j not in index})
    if missing:
        raise FitInputError(
            f"{source}: a different skeleton: no joint {', '.join(map(str, missing))} "
            f"(bone map {bonemap.name!r}; its joints: {', '.join(list(index)[:12])}...)"
        )
    axes, to_m = bonemap.axes.matrix(), UNITS[bonemap.unit]
    rot, pos = _world(take, axes, to_m)
    rest_rot, rest_pos = _world(_rest(take), axes, to_m)
    seat = index[bonemap.seat] if bonemap.seat else None
    joint = {bone: index[name] for bone, name in bonemap.joints.items()}
    chain_ends = {c.end for c in rig.chains}

    def frame_of(bone: str) -> int | None:
        """The joint whose frame ``bone``'s local transform is read in: its nearest mapped ancestor, or the seat."""
        if bone in chain_ends:
            return seat
        parent = rig.bones[rig.index[bone]].parent
        while parent >= 0:
            name = rig.bones[parent].name
            if name in joint:
                return joint[name]
            parent = rig.bones[parent].parent
        return seat

    def local(bone: str, rot_: FloatArray, pos_: FloatArray) -> tuple[FloatArray, FloatArray]:
        return _relative(rot_, pos_, frame_of(bone), joint[bone])

    out: dict[str, FloatArray] = {}
    neutral = rig.neutral
    for bone in dict.fromkeys(d.bone for d in rig.rotations):
        if bone not in joint:
            continue
        drives = [d for d in rig.rotations if d.bone == bone]
        axes_of = [int(np.argmax(np.abs(d.axis))) for d in drives]
        order = _order(axes_of)
        current, _ = local(bone, rot, pos)
        rest, _ = local(bone, rest_rot, rest_pos)
        angles = euler(np.swapaxes(rest, -1, -2) @ current, order)
        for d, axis in zip(drives, axes_of, strict=True):
            out[d.channel] = neutral.get(d.channel, 0.0) + angles[:, order.index(axis)] * d.sign
    for d in rig.translations:
        if d.bone not in joint:
            continue
        axis = int(np.argmax(np.abs(d.axis)))
        _, current = local(d.bone, rot, pos)
        _, rest = local(d.bone, rest_rot, rest_pos)
        out[d.channel] = neutral.get(d.channel, 0.0) + (current[:, axis] - rest[:, axis]) * d.sign
    for chain in rig.chains:
        if chain.end not in joint:
            continue
        _, current = local(chain.end, rot, pos)
        _, rest = local(chain.end, rest_rot, rest_pos)
        moved = current - rest
        unknown = [o for o in chain.target if o.channel not in out and o.channel in RIDER_INDEX]
        for o in chain.target:
            if o.channel in out:  # already read (the seat): its share of the move comes off
                moved = moved - np.outer(out[o.channel] - neutral.get(o.channel, 0.0), o.axis) * o.sign
        stretched = _at_full_reach(chain, joint, pos, rest_pos)
        for o in unknown:
            axis = int(np.argmax(np.abs(o.axis)))
            out[o.channel] = np.where(stretched, np.nan, neutral.get(o.channel, 0.0) + moved[:, axis] * o.sign)
    if bonemap.read is not None:
        unread = [n for n in bonemap.read if n not in out]
        if unread:
            raise FitInputError(
                f"{source}: bone map {bonemap.name!r} reads {', '.join(unread)}, which no mapped joint moves"
            )
        return {name: out[name] for name in RIDER_NAMES if name in bonemap.read}
    return {name: out[name] for name in RIDER_NAMES if name in out}


def read_bvh_rider(path: str, horse_scale: float, bonemap: str | None = None) -> tuple[RiderTake, list[str]]:
    """A BVH rider take in the horse's length unit (``horse_scale`` rig units per unit), and notes."""
    bmap = load_bonemap(bonemap)
    take = read_bvh(path)
    channels = rider_channels(take, bmap, path)
    if not channels:
        raise FitInputError(f"{path}: bone map {bmap.name!r} reads no rider channel from this file")
    names = tuple(channels)
    to_horse = METRES / horse_scale
    values = np.column_stack([channels[n] * (to_horse if lookup(n).kind is Kind.TRANSLATION else 1.0) for n in names])
    t = np.arange(values.shape[0], dtype=np.float64) * take.frame_time
    mapped = set(bmap.joints.values()) | {bmap.seat}
    unused = [n for n in take.names if n not in mapped]
    notes = [f"{path}: bone map {bmap.name!r}: {len(names)} rider channels read"]
    missing = {n: int(np.isnan(channels[n]).sum()) for n in names if np.isnan(channels[n]).any()}
    if missing:
        notes.append(
            f"{path}: frames with a limb at full reach (its target unreadable, left out): "
            + ", ".join(f"{n} {k}" for n, k in missing.items())
        )
    if unused:
        notes.append(
            f"{path}: joints not in the map (not read): {', '.join(unused[:8])}" + (" ..." if len(unused) > 8 else "")
        )
    return RiderTake(Path(path).name, t, names, values, sha256(path)), notes
