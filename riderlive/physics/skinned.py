"""The cheap character strands: the skinned tail's one strand and the rider's braid, in one solver state.

Column 0 of the strand arrays is the tail, column 1 the braid: one solver state and
one call serve both (for arrays this small, calls cost more than arithmetic). Each
strand drives a bone chain (:mod:`riderlive.physics.chain`); the tail's chain has the
fan-out sub-chains. The first frame is derived from the bones' rest pose: the bones
lie along the dock (head) direction, and the strand vertices are the bone joints.

Everything collides with everything: the tail with the hindquarters and hind legs,
the braid with the rider's back (and, when it swings that far, the horse).

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
from riderlive.physics.attach import DOCK, HEAD, HINDQUARTERS, UPRIGHT, Body, Frame, pose
from riderlive.physics.chain import ChainModel, ChainState
from riderlive.physics.collision import Capsules
from riderlive.physics.config import PhysicsConfig
from riderlive.physics.drive import Drive
from riderlive.physics.reference import segment_lengths
from riderlive.physics.strands import StrandModel, StrandState

FloatArray = npt.NDArray[np.float64]
TAIL, BRAID = 0, 1


@dataclass(frozen=True, eq=False)
class SkinnedState:
    """Strand state (V, 3, 2) and bone-chain state (V-1, 3, 2); ``parents`` are the anchors' parent frames."""

    strands: StrandState
    bones: ChainState
    parents: tuple[Frame, Frame]


@dataclass(frozen=True, eq=False)
class Anchors:
    """Pinned vertices (2, 3, 2), bone 0 up vectors (3, 2), colliders and parent frames at one instant."""

    pins: FloatArray
    up: FloatArray
    colliders: Capsules
    parents: tuple[Frame, Frame]


@dataclass(frozen=True, eq=False)
class SkinnedModel:
    """Solver model for tail + braid strands, chain model, the body they hang from, and the config."""

    strands: StrandModel
    bones: ChainModel
    config: PhysicsConfig
    body: Body
    _posing: tuple[FloatArray, FloatArray, FloatArray, float, FloatArray, float, float] = field(init=False, repr=False)
    _constants: tuple[Any, ...] = field(init=False, repr=False)
    """Every argument of :func:`advance` after the state and the drive, gathered once."""

    def __post_init__(self) -> None:
        b, cfg = self.body, self.config
        roots = (float(cfg.skinned.strand.root_length), float(cfg.rider.braid.root_length))
        posing = (b.points, b.dock_rest, b.braid_rest, b.lift_limit, b.radius, *roots)
        object.__setattr__(self, "_posing", posing)
        object.__setattr__(self, "_constants", (*posing, *self.strands.solver, *self.bones.solver))

    @staticmethod
    def build(config: PhysicsConfig) -> SkinnedModel:
        """The model for ``config``."""
        tail, braid = config.skinned.strand, config.rider.braid
        if tail.vertices != braid.vertices:
            raise ValueError("the skinned tail and the braid must have the same number of vertices")
        rest = np.concatenate(
            (segment_lengths(tail, np.array([tail.length])), segment_lengths(braid, np.array([braid.length]))), axis=1
        )
        model = StrandModel(
            rest=rest,
            inv_mass=1.0,
            bend=np.array([tail.bend, braid.bend]),
            pinned=2,
            dt=1.0 / config.rate,
            iterations=max(tail.iterations, braid.iterations),
            damping=np.array([tail.damping, braid.damping]),
            collision_passes=config.collision_passes,
        )
        sk = config.skinned
        bones = ChainModel(
            dt=model.dt,
            twist_rate=sk.twist_rate,
            fan_gain=sk.fan_gain,
            fan_max=sk.fan_max,
            fan_time=sk.fan_time,
            fan_profile=chain.fan_profile(tail.vertices - 1, [sk.subchains > 0, False]),
        )
        return SkinnedModel(model, bones, config, Body(config.horse, config.rider))

    def anchors(self, drive: Drive) -> Anchors:
        """Where the tail's dock and the braid's tie are, and what they collide with, for ``drive``."""
        points, dock_rest, braid_rest, lift_limit, radius, tail_root, braid_root = self._posing
        horse, rider = _contiguous(drive.horse), _rider(drive)
        origins, rotations, a, b = pose(horse, rider, points, dock_rest, braid_rest, lift_limit)
        pins, up = anchor_pins(origins, rotations, tail_root, braid_root)
        parents = (Frame(origins[HINDQUARTERS], rotations[HINDQUARTERS]), Frame(origins[HEAD], rotations[HEAD]))
        return Anchors(pins, up, Capsules(a, b, radius), parents)

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
        parents = (Frame(origins[HINDQUARTERS], rotations[HINDQUARTERS]), Frame(origins[HEAD], rotations[HEAD]))
        return SkinnedState(StrandState(x, prev), ChainState(axis, up, velocity, fan), parents)


def _contiguous(a: FloatArray) -> FloatArray:
    return np.ascontiguousarray(a, dtype=np.float64)


def _rider(drive: Drive) -> FloatArray:
    return UPRIGHT if drive.rider is None else _contiguous(drive.rider)


# ----------------------------------------------------------------------------- the kernels


@kernel
def anchor_pins(
    origins: FloatArray, rotations: FloatArray, tail_root: float, braid_root: float
) -> tuple[FloatArray, FloatArray]:
    """The pinned vertices (2, 3, 2) and bone 0 up vectors (3, 2) from the posed dock and braid frames.

    Each strand's root sits at its frame's origin, its second vertex ``root`` metres
    along the frame's x; bone 0's up is the frame's y.
    """
    pins, up = np.empty((2, 3, 2)), np.empty((3, 2))
    for column, frame, root in ((TAIL, DOCK, tail_root), (BRAID, BRAID_FRAME, braid_root)):
        for c in range(3):
            pins[0, c, column] = origins[frame, c]
            pins[1, c, column] = origins[frame, c] + rotations[frame, c, 0] * root
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
    lift_limit: float,
    radius: FloatArray,
    tail_root: float,
    braid_root: float,
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
    origins, rotations, cap_a, cap_b = pose(horse, rider, points, dock_rest, braid_rest, lift_limit)
    pins, anchor_up = anchor_pins(origins, rotations, tail_root, braid_root)
    new, new_prev = strands.advance(
        x, prev, pins, cap_a, cap_b, radius, rest, w, bend, keep, pinned, iterations, collision_passes, bends,
        collide_each, fall, leader,
    )  # fmt: skip
    new_axis, new_up, velocity, new_fan = chain.follow(
        axis, up, fan, new, anchor_up, fan_profile, dt, twist_share, fan_share, fan_gain, fan_max
    )
    return new, new_prev, new_axis, new_up, velocity, new_fan, origins, rotations
