"""A motion platform's mechanism as numbers: joints, actuator ranges and speeds, home, park.

Frame: the rig frame of :mod:`riderlive.channels` (right-handed, +X forward, +Y up,
+Z to the right), origin at the centre of the base joints, lengths in metres, angles
in degrees. A **pose** is ``(tx, ty, tz, rx, ry, rz)``: where the cue centre is (m)
and how the platform is turned about it, ``R = Ry(ry) Rz(rz) Rx(rx)`` (yaw, then
pitch, then roll, each about the already turned axes): +rx rolls to the right, +ry
turns to the left, +rz lifts the nose, like the saddle channels. The **cue centre**
is a point fixed to the platform (the saddle's seat, say) that the cue rotates about,
so a pitch does not also push the rider forward.

**Actuator positions**: a linear actuator's extension from fully retracted (m); a
rotary actuator's arm angle above the horizontal (deg). Limits, speeds and
accelerations are in those units, per actuator.

:class:`Geometry` is built from a validated platform file by
:func:`riderlive.platform.mechanism.config.load_platform`; :func:`hexagon` lays out the usual
6-6 Stewart joints.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

POSE_AXES: tuple[str, ...] = ("tx", "ty", "tz", "rx", "ry", "rz")
"""The pose's components, in the order of every pose tuple and array (the saddle channels' order)."""

Vec3 = tuple[float, float, float]
Pose = tuple[float, float, float, float, float, float]


class Kind(enum.Enum):
    """The mechanisms riderlive drives."""

    STEWART_LINEAR = "stewart_linear"
    """Six linear actuators between base and platform joints (a 6-6 Stewart-Gough platform)."""
    STEWART_ROTARY = "stewart_rotary"
    """Six rotary actuators: a crank arm on each shaft, a rod from the arm's tip to the platform."""
    HEAVE_PITCH_ROLL = "heave_pitch_roll"
    """Three linear actuators under a platform that a centre guide keeps from surging, swaying and turning."""

    @property
    def legs(self) -> int:
        return 3 if self is Kind.HEAVE_PITCH_ROLL else 6

    @property
    def rotary(self) -> bool:
        return self is Kind.STEWART_ROTARY

    @property
    def axes(self) -> tuple[bool, ...]:
        """Which pose components the mechanism can move (in :data:`POSE_AXES` order)."""
        if self is Kind.HEAVE_PITCH_ROLL:
            return (False, True, False, True, False, True)
        return (True,) * 6

    @property
    def unit(self) -> str:
        """The unit of an actuator position."""
        return "deg" if self.rotary else "m"


@dataclass(frozen=True)
class Geometry:
    """Everything the kinematics and the limits need, as plain numbers.

    ``base[i]`` is actuator i's base joint (a linear actuator's lower joint, a rotary
    actuator's shaft centre) in the base frame; ``platform[i]`` its platform joint in
    the platform frame, measured from the cue centre. ``lower``/``upper`` are the soft
    limits normal running stays within, ``hard_lower``/``hard_upper`` the mechanical
    ends; ``max_speed``/``max_accel`` are per actuator (m/s, m/s^2 or deg/s, deg/s^2).
    ``home`` and ``park`` are poses of the cue centre in the base frame.
    """

    kind: Kind
    base: tuple[Vec3, ...]
    platform: tuple[Vec3, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    hard_lower: tuple[float, ...]
    hard_upper: tuple[float, ...]
    max_speed: tuple[float, ...]
    max_accel: tuple[float, ...]
    home: Pose
    park: Pose
    centre: Vec3 = (0.0, 0.0, 0.0)
    """The cue centre in the platform frame, from the platform's origin (for drawing and docs)."""
    min_length: float = 0.0
    """Linear: joint-to-joint length when fully retracted (m); position = length - min_length."""
    arm: float = 0.0
    """Rotary: crank arm length, shaft axis to the rod's joint (m)."""
    rod: float = 0.0
    """Rotary: rod length, joint to joint (m)."""
    arm_direction: tuple[tuple[float, float], ...] = ()
    """Rotary: the horizontal unit vector ``(x, z)`` an arm points along at 0 deg."""

    def __post_init__(self) -> None:
        n = self.kind.legs
        for name in ("base", "platform", "lower", "upper", "hard_lower", "hard_upper", "max_speed", "max_accel"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"{name} needs {n} entries for a {self.kind.value} platform")
        if self.kind.rotary and len(self.arm_direction) != n:
            raise ValueError(f"arm_direction needs {n} entries")

    @property
    def legs(self) -> int:
        return self.kind.legs

    @property
    def unit(self) -> str:
        return self.kind.unit

    def platform_origin(self, pose: Pose) -> Vec3:
        """Where the platform's own origin is for a pose of the cue centre (base frame, m)."""
        r = rotation(pose[3], pose[4], pose[5])
        c = self.centre
        return (
            pose[0] - (r[0][0] * c[0] + r[0][1] * c[1] + r[0][2] * c[2]),
            pose[1] - (r[1][0] * c[0] + r[1][1] * c[1] + r[1][2] * c[2]),
            pose[2] - (r[2][0] * c[0] + r[2][1] * c[1] + r[2][2] * c[2]),
        )


def rotation(rx: float, ry: float, rz: float) -> tuple[Vec3, Vec3, Vec3]:
    """The rotation matrix ``Ry(ry) Rz(rz) Rx(rx)`` (degrees), as rows."""
    a, b, g = math.radians(rx), math.radians(ry), math.radians(rz)
    ca, sa, cb, sb, cg, sg = math.cos(a), math.sin(a), math.cos(b), math.sin(b), math.cos(g), math.sin(g)
    return (
        (cb * cg, -cb * sg * ca + sb * sa, cb * sg * sa + sb * ca),
        (sg, cg * ca, -cg * sa),
        (-sb * cg, sb * sg * ca + cb * sa, -sb * sg * sa + cb * ca),
    )


def hexagon(
    base_radius: float, base_spread_deg: float, platform_radius: float, platform_spread_deg: float
) -> tuple[tuple[Vec3, ...], tuple[Vec3, ...]]:
    """The usual 6-6 layout: joints in three pairs on a circle, platform pairs turned by 60 deg.

    Angles run from +X toward +Z (to the right), a joint at angle ``a`` on radius ``r``
    sits at ``(r cos a, 0, r sin a)``. Base pairs are centred on 0, 120 and 240 deg,
    ``base_spread_deg`` apart; platform pairs on 60, 180 and 300 deg. Actuator ``2k``
    runs from the base joint at ``120k - spread/2`` to the platform joint at
    ``120k - 60 + spread/2``, actuator ``2k + 1`` from ``120k + spread/2`` to
    ``120k + 60 - spread/2``: the layout is symmetric about the X-Y plane (left and right).
    """
    base: list[Vec3] = []
    platform: list[Vec3] = []
    for k in range(3):
        for side in (-1.0, 1.0):
            b = math.radians(120.0 * k + side * base_spread_deg / 2.0)
            p = math.radians(120.0 * k + side * (60.0 - platform_spread_deg / 2.0))
            base.append((base_radius * math.cos(b), 0.0, base_radius * math.sin(b)))
            platform.append((platform_radius * math.cos(p), 0.0, platform_radius * math.sin(p)))
    return tuple(base), tuple(platform)


def tangential_arms(base: tuple[Vec3, ...]) -> tuple[tuple[float, float], ...]:
    """Rotary arms at 0 deg pointing along the base circle, each toward its own platform joint.

    In :func:`hexagon`'s layout actuator ``2k`` reaches back (to smaller angles) and
    ``2k + 1`` forward, so the arms of a pair point away from each other.
    """
    out: list[tuple[float, float]] = []
    for i, (x, _, z) in enumerate(base):
        a = math.atan2(z, x) + (math.pi / 2.0 if i % 2 else -math.pi / 2.0)
        out.append((math.cos(a), math.sin(a)))
    return tuple(out)
