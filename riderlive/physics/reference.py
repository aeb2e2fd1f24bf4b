"""The many-strand reference tail: hundreds of independent strands rooted across the dock.

Each strand has 12 vertices (by default); its first segment is the dock itself,
pinned in the dock frame, so the strands swing with the horse's pitch and twist and
lag behind its accelerations. Lengths and bending stiffness vary a little from
strand to strand (a seeded random draw), which gives the tail its volume. All
strands collide with the hindquarters and the hind legs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from riderlive.physics import strands
from riderlive.physics.attach import DOCK, Body, Frame
from riderlive.physics.config import PhysicsConfig, StrandParams
from riderlive.physics.drive import Drive
from riderlive.physics.strands import MAX_BEND, StrandModel, StrandState

FloatArray = npt.NDArray[np.float64]


def segment_lengths(params: StrandParams, total: FloatArray) -> FloatArray:
    """Rest lengths (V-1, N): the pinned root segment, then equal segments to ``total`` (N,)."""
    free = params.vertices - 2
    rest = np.empty((params.vertices - 1, len(total)))
    rest[0] = params.root_length
    rest[1:] = (np.maximum(total - params.root_length, 1e-3) / free)[None, :]
    return rest


def pinned_vertices(frame: Frame, offsets: FloatArray, root_length: float) -> FloatArray:
    """The two pinned vertices (2, 3, N) of strands rooted at ``offsets`` (3, N) in the dock frame."""
    base = frame.origin[:, None] + frame.rotation @ offsets
    tip = base + (frame.rotation[:, 0] * root_length)[:, None]
    return np.stack((base, tip))


@dataclass(frozen=True, eq=False)
class ReferenceModel:
    """The strands' solver model, root offsets (3, N) in the dock frame, the config and the body they hang from."""

    strands: StrandModel
    root_offsets: FloatArray
    config: PhysicsConfig
    body: Body

    @staticmethod
    def build(config: PhysicsConfig) -> ReferenceModel:
        ref = config.reference
        rng = np.random.default_rng(ref.seed)
        n = ref.strands
        total = ref.strand.length * (1.0 - rng.uniform(0.0, ref.length_jitter, n))
        bend = np.clip(ref.strand.bend * (1.0 + rng.uniform(-ref.bend_jitter, ref.bend_jitter, n)), 0.0, MAX_BEND)
        radius = ref.dock_radius * np.sqrt(rng.uniform(0.0, 1.0, n))
        angle = rng.uniform(0.0, 2.0 * np.pi, n)
        offsets = np.stack((np.zeros(n), radius * np.cos(angle), radius * np.sin(angle)))
        model = StrandModel(
            rest=segment_lengths(ref.strand, total),
            inv_mass=1.0,
            bend=bend,
            pinned=2,
            dt=1.0 / config.rate,
            iterations=ref.strand.iterations,
            damping=ref.strand.damping,
            collision_passes=config.collision_passes,
        )
        return ReferenceModel(model, offsets, config, Body(config.horse, config.rider))

    def initial(self, drive: Drive) -> StrandState:
        """Straight strands along the dock, at rest, for the first frame."""
        frame = self.body.pose(drive.horse).frame(DOCK)
        pins = pinned_vertices(frame, self.root_offsets, self.config.reference.strand.root_length)
        direction = np.broadcast_to(frame.rotation[:, :1], (3, self.strands.n_strands))
        return strands.rest_state(self.strands, pins[0], np.ascontiguousarray(direction))

    def step(self, state: StrandState, drive: Drive) -> StrandState:
        """One fixed step toward the horse pose of ``drive`` (the horse alone: the rider is not posed)."""
        pose = self.body.pose(drive.horse)
        pins = pinned_vertices(pose.frame(DOCK), self.root_offsets, self.config.reference.strand.root_length)
        return strands.step(self.strands, state, pins, pose.horse_colliders)


def mean_tip(state: StrandState) -> FloatArray:
    """The mean position (3,) of the strands' last vertices, world metres."""
    return np.asarray(state.x[-1].mean(axis=1), dtype=np.float64)
