"""The cheap character strands: the skinned tail's one strand, the rider's braid and coat-skirt flaps, in one state.

Column 0 of the strand arrays is the tail, column 1 the braid, columns 2 and 3 the
left and right cloth flaps: one solver state and one call serve all four (for arrays
this small, calls cost more than arithmetic). Each strand drives a bone chain
(:mod:`riderlive.physics.chain`); the tail's chain has the fan-out sub-chains. The
first frame is derived from the bones' rest pose: the bones lie along the dock (tie)
direction, and the strand vertices are the bone joints.

Everything collides with everything: the tail with the hindquarters and hind legs,
the braid and the flaps with the rider's back (and, when they swing that far, the horse).

One step is one compiled call (:func:`advance`): posing (:func:`riderlive.physics.attach.pose`),
the strand step (:func:`riderlive.physics.strands.advance`) and the chains
(:func:`riderlive.physics.chain.follow`), the same kernels the other models call.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from riderlive.fastpath import kernel
from riderlive.physics import chain, strands
from riderlive.physics.attach import BRAID as BRAID_FRAME
from riderlive.physics.attach import CLOTH_L as CLOTH_L_FRAME
from riderlive.physics.attach import CLOTH_R as CLOTH_R_FRAME
from riderlive.physics.attach import DOCK, HEAD, HINDQUARTERS, HIPS, UPRIGHT, Body, Frame, pose
from riderlive.physics.chain import ChainModel, ChainState
from riderlive.physics.collision import Capsules
from riderlive.physics.config import PhysicsConfig
from riderlive.physics.drive import Drive
from riderlive.physics.reference import segment_lengths
from riderlive.physics.strands import StrandModel, StrandState

FloatArray = npt.NDArray[np.float64]
TAIL, BRAID, CLOTH_L, CLOTH_R = range(4)
"""Strand (and chain) columns: the skinned tail, the braid, the left and right cloth flaps."""


@dataclass(frozen=True, eq=False)
class SkinnedState:
    """Strand state (V, 3, 4) and bone-chain state (V-1, 3, 4); ``parents`` are the anchors' parent frames
    (hindquarters, head, hips, hips), one per column."""

    strands: StrandState
    bones: ChainState
    parents: tuple[Frame, ...]


@dataclass(frozen=True, eq=False)
class Anchors:
    """Pinned vertices (2, 3, 4), bone 0 up vectors (3, 4), colliders and parent frames at one instant."""

    pins: FloatArray
    up: FloatArray
    colliders: Capsules
    parents: tuple[Frame, ...]


@dataclass(frozen=True, eq=False)
class SkinnedModel:
    """Solver model for the tail, braid and flap strands, chain model, the body they hang from, and the config."""

    strands: StrandModel
    bones: ChainModel
    config: PhysicsConfig
    body: Body
    _posing: tuple[Any, ...] = field(init=False, repr=False)
    _constants: tuple[Any, ...] = field(init=False, repr=False)
    """Every argument of :func:`advance` after the state and the drive, gathered once."""

    def __post_init__(self) -> None:
        b, cfg = self.body, self.config
        cloth = cfg.rider.cloth.root_length
        roots = np.array([cfg.skinned.strand.root_length, cfg.rider.braid.root_length, cloth, cloth])
        posing = (b.points, b.dock_rest, b.braid_rest, b.cloth_rest, b.lift_limit, b.radius, roots)
        object.__setattr__(self, "_posing", posing)
        object.__setattr__(self, "_constants", (*posing, *self.strands.solver, *self.bones.solver))

    @staticmethod
    def build(config: PhysicsConfig) -> SkinnedModel:
        """The model for ``config``."""
        kinds = (config.skinned.strand, config.rider.braid, config.rider.cloth, config.rider.cloth)
        if len({k.vertices for k in kinds}) != 1:
            raise ValueError(
                "skinned.strand, rider.braid and rider.cloth must have the same number of vertices "
                f"(got {kinds[0].vertices}, {kinds[1].vertices}, {kinds[2].vertices})"
            )
        model = StrandModel(
            rest=np.concatenate([segment_lengths(k, np.array([k.length])) for k in kinds], axis=1),
            inv_mass=1.0,
            bend=np.array([k.bend for k in kinds]),
            pinned=2,
            dt=1.0 / config.rate,
            iterations=max(k.iterations for k in kinds),
            damping=np.array([k.damping for k in kinds]),
            collision_passes=config.collision_passes,
        )
        sk = config.skinned
        bones = ChainModel(
            dt=model.dt,
            twist_rate=sk.twist_rate,
            fan_gain=sk.fan_gain,
            fan_max=sk.fan_max,
            fan_time=sk.fan_time,
            fan_profile=chain.fan_profile(kinds[0].vertices - 1, [sk.subchains > 0, False, False, False]),
        )
        return SkinnedModel(model, bones, config, Body(config.horse, config.rider))

    def anchors(self, drive: Drive) -> Anchors:
        """Where the tail's dock and the braid's and flaps' ties are, and what they collide with, for ``drive``."""
        points, dock_rest, braid_rest, cloth_rest, lift_limit, radius, roots = self._posing
        horse, rider = _contiguous(drive.horse), _rider(drive)
        origins, rotations, a, b = pose(horse, rider, points, dock_rest, braid_rest, cloth_rest, lift_limit)
        pins, up = anchor_pins(origins, rotations, roots)
        return Anchors(pins, up, Capsules(a, b, radius), _parents(origins, rotations))

    def initial(self, drive: Drive) -> SkinnedState:
        """Bones in their rest pose along the anchors; the strands are derived from the bone joints."""
        anchors = self.anchors(drive)
        direction = anchors.pins[1] - anchors.pins[0]
        direction /= np.linalg.norm(direction, axis=0, keepdims=True)
        joints = strands.rest_state(self.strands, anchors.pins[0], direction)
        return SkinnedState(joints, chain.rest_state(joints.x, anchors.up), anchors.parents)

    def step(self, state: SkinnedState, drive: Drive) -> SkinnedState:
        """One fixed step: posing, the strands, then the bone chains that follow them (one compiled call)."""
        s, b = state.strands, state.bones
        x, prev, axis, up, velocity, fan, origins, rotations = advance(
            s.x,
            s.x_prev,
            b.axis,
            b.up,
            b.fan,
            _contiguous(drive.horse),
            _rider(drive),
            *self._constants,
        )
        return SkinnedState(StrandState(x, prev), ChainState(axis, up, velocity, fan), _parents(origins, rotations))


PARENTS = (HINDQUARTERS, HEAD, HIPS, HIPS)
"""The posed frame each column's bone 0 is relative to: the tail's, the braid's, the flaps'."""


def _parents(origins: FloatArray, rotations: FloatArray) -> tuple[Frame, ...]:
    return tuple(Frame(origins[f], rotations[f]) for f in PARENTS)


def _contiguous(a: FloatArray) -> FloatArray:
    return np.ascontiguousarray(a, dtype=np.float64)


def _rider(drive: Drive) -> FloatArray:
    return UPRIGHT if drive.rider is None else _contiguous(drive.rider)


# ----------------------------------------------------------------------------- the kernels


@kernel
def anchor_pins(origins: FloatArray, rotations: FloatArray, roots: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The pinned vertices (2, 3, 4) and bone 0 up vectors (3, 4) from the posed dock, braid and flap frames.

    Each strand's root sits at its frame's origin, its second vertex ``roots[column]``
    metres along the frame's x; bone 0's up is the frame's y.
    """
    pins, up = np.empty((2, 3, 4)), np.empty((3, 4))
    for column, frame in ((TAIL, DOCK), (BRAID, BRAID_FRAME), (CLOTH_L, CLOTH_L_FRAME), (CLOTH_R, CLOTH_R_FRAME)):
        for c in range(3):
            pins[0, c, column] = origins[frame, c]
            pins[1, c, column] = origins[frame, c] + rotations[frame, c, 0] * roots[column]
            up[c, column] = rotations[frame, c, 1]
    return pins, up


@kernel
def advance(  # noqa: PLR0917
    x: FloatArray,
    prev: FloatArray,
    axis: FloatArray,
    up: FloatArray,
    fan: FloatArray,
    horse: FloatArray,
    rider: FloatArray,
    points: FloatArray,
    dock_rest: FloatArray,
    braid_rest: FloatArray,
    cloth_rest: FloatArray,
    lift_limit: float,
    radius: FloatArray,
    roots: FloatArray,
    rest: FloatArray,
    w: FloatArray,
    bend: FloatArray,
    keep: FloatArray,
    pinned: int,
    iterations: int,
    collision_passes: int,
    bends: bool,
    collide_each: bool,
    fall: float,
    leader: float,
    fan_profile: FloatArray,
    dt: float,
    twist_share: float,
    fan_share: float,
    fan_gain: float,
    fan_max: float,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Pose, step the strands, follow with the chains.

    Returns the new x, x_prev, axis, up, velocity, fan, and the posed frames' origins and rotations.
    """
    origins, rotations, cap_a, cap_b = pose(horse, rider, points, dock_rest, braid_rest, cloth_rest, lift_limit)
    pins, anchor_up = anchor_pins(origins, rotations, roots)
    new, new_prev = strands.advance(
        x, prev, pins, cap_a, cap_b, radius, rest, w, bend, keep, pinned, iterations, collision_passes, bends,
        collide_each, fall, leader,
    )  # fmt: skip
    new_axis, new_up, velocity, new_fan = chain.follow(
        axis, up, fan, new, anchor_up, fan_profile, dt, twist_share, fan_share, fan_gain, fan_max
    )
    return new, new_prev, new_axis, new_up, velocity, new_fan, origins, rotations
