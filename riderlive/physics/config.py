"""Typed parameters of the tail and braid (``config/physics/*.toml``), validated at load.

Lengths in metres, times in seconds, rates in 1/s; points are (x forward, y up,
z right) in the frame named by their docstring.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import pydantic

from riderlive.configfile import CONFIG_DIR, StrictModel, load

Vec3 = tuple[float, float, float]
Positive = Annotated[float, pydantic.Field(gt=0.0)]
NonNegative = Annotated[float, pydantic.Field(ge=0.0)]
Fraction = Annotated[float, pydantic.Field(ge=0.0, le=1.0)]
DEFAULT_FILE = CONFIG_DIR / "physics" / "tail.toml"


class StrandParams(StrictModel):
    """One kind of strand: how long, how many vertices, how stiff."""

    length: Positive = 0.92
    """Total length including the pinned first segment."""
    root_length: Positive = 0.12
    """The pinned first segment (the dock / the braid's tie), rigid with its parent."""
    vertices: Annotated[int, pydantic.Field(ge=3, le=64)] = 12
    bend: Annotated[float, pydantic.Field(ge=0.0, le=0.5)] = 0.25
    """Fraction of the way to the neighbours' line per step (0 = a chain, 0.5 = stiffest stable)."""
    damping: NonNegative = 0.3
    """Velocity damping, 1/s."""
    iterations: Annotated[int, pydantic.Field(ge=1, le=64)] = 4


class ReferenceTail(StrictModel):
    """The many-strand reference tail."""

    strands: Annotated[int, pydantic.Field(ge=1, le=100_000)] = 400
    strand: StrandParams = StrandParams()
    length_jitter: Fraction = 0.12
    """Each strand's length is ``length * (1 - U(0, jitter))``."""
    bend_jitter: Fraction = 0.3
    """Each strand's bend is ``bend * (1 + U(-jitter, jitter))`` (clipped to [0, 0.5])."""
    dock_radius: NonNegative = 0.035
    """Strand roots are spread over a disc of this radius across the dock."""
    seed: int = 7


class SkinnedTail(StrictModel):
    """The one-strand tail and its 11-bone chain with three fan-out sub-chains."""

    strand: StrandParams = StrandParams(length=0.865, iterations=1)
    """Length 0.865 m: the reference strands' mean (0.92 m less half the 12 % jitter), which it is to match."""
    twist_rate: Positive = 200.0
    """Torsion spring: relative twist between neighbour bones decays at this rate, 1/s."""
    fan_gain: NonNegative = 0.04
    """Sub-chain distance per rad/s of the centre bone's torsional velocity, metres, at the tip."""
    fan_max: NonNegative = 0.08
    fan_time: Positive = 0.08
    """Time constant of the sub-chains swinging out and back, seconds."""
    subchains: Annotated[int, pydantic.Field(ge=0, le=8)] = 3


class HorseBody(StrictModel):
    """Where the rear pivot and hind hooves stand (root frame), the dock and the shapes (hindquarters frame).

    The horse's ``rearPivot.t*`` and hoof ``t*`` channels are displacements from
    standing; these rest positions turn them into places on the body.
    """

    pivot_rest: Vec3 = (-0.55, 1.05, 0.0)
    """The rear pivot (hips) when ``rearPivot.t*`` are 0, in the root frame."""
    hind_hoof_rest: Vec3 = (-0.65, 0.0, 0.17)
    """The hind hooves' square-standing spot in the root frame (z mirrored for the left hoof)."""
    dock_offset: Vec3 = (-0.5, 0.42, 0.0)
    dock_direction: Vec3 = (-0.8, -0.6, 0.0)
    """Direction of the dock (the pinned first segment), away from the horse."""
    hindquarters_centre: Vec3 = (-0.2, 0.2, 0.0)
    hindquarters_radius: Positive = 0.32
    hip_offset: Vec3 = (-0.15, -0.05, 0.17)
    """Hip end of each hind-leg capsule (z mirrored for the left leg)."""
    leg_radius: Positive = 0.07


class RiderBody(StrictModel):
    """A simple rider: seat in the hindquarters frame, the rest in the spine's frame."""

    seat_offset: Vec3 = (0.55, 0.5, 0.0)
    lift_limit: NonNegative = 0.2
    head_height: Positive = 0.72
    back_bottom: Vec3 = (-0.02, 0.12, 0.0)
    back_top: Vec3 = (-0.02, 0.5, 0.0)
    back_radius: Positive = 0.14
    braid_offset: Vec3 = (-0.1, 0.02, 0.0)
    """Root of the braid in the head frame (the back of the head)."""
    braid_direction: Vec3 = (-0.3, -1.0, 0.0)
    hair_up_gain: float = 2.0
    """The braid's tie tilts up and back by this many degrees per unit of ``hair.up`` (section 8.9)."""
    hair_side_gain: float = 20.0
    """... and to the rider's right by this many degrees per unit of ``hair.side``."""
    braid: StrandParams = StrandParams(length=0.45, root_length=0.04, bend=0.35, damping=0.5, iterations=1)
    cloth_offset: Vec3 = (-0.1, 0.0, 0.2)
    """Root of the right coat-skirt flap in the hips frame (the spine's frame at the seat); z mirrored for the left."""
    cloth_direction: Vec3 = (-0.3, -1.0, 0.3)
    """The right flap's tie at rest, in the hips frame: down, a little back and out (z mirrored for the left)."""
    cloth_up_gain: float = 3.0
    """Both flaps' ties tilt up and back (about the hips' z) by this many degrees per unit of ``cloth.up`` (8.9)."""
    cloth_side_gain: float = 3.0
    """... and to the rider's right (about the hips' x) by this many degrees per unit of ``cloth.side``."""
    cloth_tilt_limit: Annotated[float, pydantic.Field(ge=0.0, le=180.0)] = 75.0
    """Each of the two tilts is limited to +- this many degrees (an absurd attribute leaves the flap finite)."""
    cloth: StrandParams = StrandParams(length=0.4, root_length=0.08, bend=0.45, damping=2.0, iterations=1)
    """Each flap: 0.4 m of coat skirt, its top 8 cm rigid with the hips (the pinned tie), stiffer and more
    damped than the braid (it must have the tail's and the braid's vertex count: one solver state)."""


class PhysicsConfig(StrictModel):
    """Everything the tail and braid need; ``rate`` is the fixed internal step rate, Hz."""

    rate: Annotated[float, pydantic.Field(ge=30.0, le=2000.0)] = 240.0
    collision_passes: Annotated[int, pydantic.Field(ge=1, le=16)] = 8
    reference: ReferenceTail = ReferenceTail()
    skinned: SkinnedTail = SkinnedTail()
    horse: HorseBody = HorseBody()
    rider: RiderBody = RiderBody()


def load_physics(path: str | Path | None = None) -> PhysicsConfig:
    """The physics config from ``path`` (default ``config/physics/tail.toml``), validated."""
    return load(PhysicsConfig, DEFAULT_FILE if path is None else path)
