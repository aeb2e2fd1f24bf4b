"""The cheap character strands: the skinned tail's one strand and the rider's braid, in one solver state.

Column 0 of the strand arrays is the tail, column 1 the braid: batching them makes one
set of NumPy calls serve both (tiny arrays cost per call, not per element). Each
strand drives a bone chain (:mod:`riderlive.physics.chain`); the tail's chain has the
fan-out sub-chains. The first frame is derived from the bones' rest pose: the bones
lie along the dock (head) direction, and the strand vertices are the bone joints.

Everything collides with everything: the tail with the hindquarters and hind legs,
the braid with the rider's back (and, when it swings that far, the horse).

``compiled`` (the default when numba is installed) runs posing, strands and chains
through :mod:`riderlive.physics.kernels`, 15-25x faster for these tiny arrays and
equal to the NumPy path within 1e-12 per step; ``compiled=False`` keeps the NumPy path.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from riderlive.physics import chain, kernels, strands
from riderlive.physics.attach import Frame, HorseAttachment, RiderAttachment
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
    """Solver model for tail + braid strands, chain model, and the config they came from.

    ``compiled``: step with the numba kernels (default when numba is installed) or NumPy.
    """

    strands: StrandModel
    bones: ChainModel
    config: PhysicsConfig
    horse: HorseAttachment
    rider: RiderAttachment
    compiled: bool = kernels.AVAILABLE
    _pose: kernels.CompiledPose | None = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if self.compiled and not kernels.AVAILABLE:
            raise ValueError("the compiled skinned tail needs numba (pip install numba); or pass compiled=False")
        cfg = self.config
        pose = (
            kernels.CompiledPose(self.horse, self.rider, cfg.skinned.strand.root_length, cfg.rider.braid.root_length)
            if self.compiled
            else None
        )
        object.__setattr__(self, "_pose", pose)

    @staticmethod
    def build(config: PhysicsConfig, compiled: bool | None = None) -> SkinnedModel:
        """The model for ``config``; ``compiled`` None means whenever numba is installed."""
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
        return SkinnedModel(
            model,
            bones,
            config,
            HorseAttachment(config.horse),
            RiderAttachment(config.rider),
            kernels.AVAILABLE if compiled is None else compiled,
        )

    def anchors(self, drive: Drive) -> Anchors:
        """Where the tail's dock and the braid's tie are, and what they collide with, for ``drive``."""
        if self._pose is not None:
            pins, up, colliders, hq, head = self._pose(drive)
            return Anchors(pins, up, colliders, (hq, head))
        cfg = self.config
        hq = self.horse.hindquarters(drive.horse)
        tail_frame = self.horse.dock(hq)
        pose = self.rider.pose(hq, drive.rider)
        head_frame = self.rider.braid(pose)
        base = np.stack((tail_frame.origin, head_frame.origin), axis=1)
        along = np.stack(
            (
                tail_frame.rotation[:, 0] * cfg.skinned.strand.root_length,
                head_frame.rotation[:, 0] * cfg.rider.braid.root_length,
            ),
            axis=1,
        )
        up = np.stack((tail_frame.rotation[:, 1], head_frame.rotation[:, 1]), axis=1)
        colliders = Capsules.concat(self.horse.colliders(drive.horse, hq), pose.back)
        return Anchors(np.stack((base, base + along)), up, colliders, (hq, pose.head))

    def initial(self, drive: Drive) -> SkinnedState:
        """Bones in their rest pose along the anchors; the strands are derived from the bone joints."""
        anchors = self.anchors(drive)
        direction = anchors.pins[1] - anchors.pins[0]
        direction /= np.linalg.norm(direction, axis=0, keepdims=True)
        joints = strands.rest_state(self.strands, anchors.pins[0], direction)
        return SkinnedState(joints, chain.rest_state(joints.x, anchors.up), anchors.parents)

    def step(self, state: SkinnedState, drive: Drive) -> SkinnedState:
        """One fixed step: the strands, then the bone chains that follow them."""
        anchors = self.anchors(drive)
        if self.compiled:
            moved = kernels.strand_step(self.strands, state.strands, anchors.pins, anchors.colliders)
            bones = kernels.chain_step(self.bones, state.bones, moved.x, anchors.up)
        else:
            moved = strands.step(self.strands, state.strands, anchors.pins, anchors.colliders)
            bones = chain.step(self.bones, state.bones, moved.x, anchors.up)
        return SkinnedState(moved, bones, anchors.parents)
