"""What the rider parts (:mod:`riderlive.rules.parts`) need of the two skeletons: the tack's geometry.

Read once from a horse rig (rein and stirrup bones) and a rider rig (arms, legs), in
the seat frame (origin on the horse's ``saddle`` bone, +x forward, +y up, +z right),
metres. A skeleton without the bones a part needs, or with absurd lengths, switches
that part off and says why in :attr:`PartsGeometry.notes`.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any

from riderlive.skeleton.quat import Vec3, norm, sub
from riderlive.skeleton.rig import Bone, Rig

REIN_LENGTH_RANGE = (0.2, 3.0)
LEATHER_LENGTH_RANGE = (0.2, 1.5)
ARM_LENGTH_RANGE = (0.2, 1.5)
"""Skeleton lengths (m) the parts accept; outside, the part is off (a note says so)."""


@dataclass(frozen=True)
class PartsGeometry:
    """What the parts need of the two skeletons, in the seat frame, metres.

    ``None`` for a part the skeletons cannot carry; :attr:`notes` says why.
    """

    neck: Vec3 | None = None
    """The horse's neck joint (withers)."""
    poll: Vec3 = (0.0, 0.0, 0.0)
    """The head joint in the neck's frame."""
    rings: tuple[Vec3, Vec3] = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    """Left and right bit rings in the head's frame."""
    hands: tuple[Vec3, Vec3] = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    """The rider's rest hands (wrists)."""
    shoulders: tuple[Vec3, Vec3] = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    """The rider's rest shoulder joints (upper arm roots)."""
    lean_pivot: Vec3 = (0.0, 0.0, 0.0)
    """Where the trunk's forward lean turns the shoulders (the rider's ``lower_back`` joint)."""
    arm_length: float = 0.0
    reins: tuple[float, float] = (1.0, 1.0)
    """Each rest hand's distance to its bit ring (neck and head at rest): the reins' rest lengths."""
    ankles: tuple[Vec3, Vec3] | None = None
    """The rider's rest ankles (the leg IK's end); None: no stirrups."""
    centres: tuple[Vec3, Vec3] = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    """Each stirrup bar moved by the rest ankle-to-ball offset: the ankle stays within a leather of it."""
    leathers: tuple[float, float] = (0.0, 0.0)
    notes: tuple[str, ...] = ()

    @property
    def has_reins(self) -> bool:
        return self.neck is not None

    @property
    def has_stirrups(self) -> bool:
        return self.ankles is not None

    @classmethod
    def from_rigs(cls, horse: Rig, rider: Rig, attach: str = "saddle") -> PartsGeometry:
        """Read the geometry from a horse rig (rein and stirrup bones) and a rider rig (arms, legs).

        The rider's origin sits on the horse's ``attach`` bone. Missing bones or lengths
        outside :data:`REIN_LENGTH_RANGE`, :data:`LEATHER_LENGTH_RANGE`,
        :data:`ARM_LENGTH_RANGE` turn a part off with a note.
        """
        h_rest = dict(zip(horse.names, horse.rest_world(), strict=True))
        r_rest = dict(zip(rider.names, rider.rest_world(), strict=True))
        h_bones = dict(zip(horse.names, horse.bones, strict=True))
        notes: list[str] = []

        def missing(rig: Rig, names: Sequence[str]) -> list[str]:
            return [n for n in names if n not in rig.index]

        if attach not in h_rest:
            return cls(notes=(f"horse skeleton has no {attach!r} bone: reins and stirrups off",))
        seat = h_rest[attach]
        fields: dict[str, Any] = {}
        rein_bones = ("neck", "head", "leftRein", "rightRein")
        arm_bones = tuple(f"{p}_{b}" for p in ("lf", "rt") for b in ("upperarm", "forearm", "hand"))
        lacking = missing(horse, rein_bones) + missing(rider, (*arm_bones, "lower_back"))
        if lacking:
            notes.append(f"no rein bones ({', '.join(lacking)}): the hands follow the seat (Appendix B)")
        elif not _chain_ok(h_bones, ("neck", "head", "leftRein")) or not _chain_ok(
            h_bones, ("neck", "head", "rightRein")
        ):
            notes.append("the rein bones are not neck -> head -> leftRein/rightRein: the hands follow the seat")
        else:
            hands = (r_rest["lf_hand"], r_rest["rt_hand"])
            shoulders = (r_rest["lf_upperarm"], r_rest["rt_upperarm"])
            arm = norm(sub(r_rest["lf_forearm"], r_rest["lf_upperarm"])) + norm(
                sub(r_rest["lf_hand"], r_rest["lf_forearm"])
            )
            rings = (h_bones["leftRein"].offset, h_bones["rightRein"].offset)
            reins = (
                norm(sub(hands[0], sub(h_rest["leftRein"], seat))),
                norm(sub(hands[1], sub(h_rest["rightRein"], seat))),
            )
            if not _within(arm, ARM_LENGTH_RANGE) or not all(_within(r, REIN_LENGTH_RANGE) for r in reins):
                notes.append(
                    f"absurd rein or arm length (reins {reins[0]:.3g}, {reins[1]:.3g} m, arm {arm:.3g} m): "
                    "the hands follow the seat"
                )
            else:
                fields.update(
                    neck=sub(h_rest["neck"], seat),
                    poll=h_bones["head"].offset,
                    rings=rings,
                    hands=hands,
                    shoulders=shoulders,
                    lean_pivot=r_rest["lower_back"],
                    arm_length=arm,
                    reins=reins,
                )
        stirrup_bones = ("leftStirrupBar", "leftStirrup", "rightStirrupBar", "rightStirrup")
        leg_bones = tuple(f"{p}_{b}" for p in ("lf", "rt") for b in ("foot", "toes"))
        lacking = missing(horse, stirrup_bones) + missing(rider, leg_bones)
        if lacking:
            notes.append(f"no stirrup bones ({', '.join(lacking)}): the feet follow Eq. 14-17 alone")
        else:
            bars = (sub(h_rest["leftStirrupBar"], seat), sub(h_rest["rightStirrupBar"], seat))
            leathers = (norm(h_bones["leftStirrup"].offset), norm(h_bones["rightStirrup"].offset))
            if not all(_within(v, LEATHER_LENGTH_RANGE) for v in leathers):
                notes.append(
                    f"absurd stirrup leathers ({leathers[0]:.3g}, {leathers[1]:.3g} m): the feet follow Eq. 14-17 alone"
                )
            else:
                ankles = (r_rest["lf_foot"], r_rest["rt_foot"])
                balls = (sub(r_rest["lf_toes"], ankles[0]), sub(r_rest["rt_toes"], ankles[1]))
                centres = (sub(bars[0], balls[0]), sub(bars[1], balls[1]))
                if not all(c[1] > a[1] for c, a in zip(centres, ankles, strict=True)):
                    notes.append("a stirrup bar below its ankle: the feet follow Eq. 14-17 alone")
                else:
                    fields.update(ankles=ankles, centres=centres, leathers=leathers)
        return cls(notes=tuple(notes), **fields)


def _within(value: float, bounds: tuple[float, float]) -> bool:
    return math.isfinite(value) and bounds[0] <= value <= bounds[1]


def _chain_ok(bones: dict[str, Bone], names: Sequence[str]) -> bool:
    """Each bone of ``names`` is the parent of the next."""
    index = {name: i for i, name in enumerate(bones)}
    return all(bones[child].parent == index[parent] for parent, child in itertools.pairwise(names))


@cache
def default_geometry() -> PartsGeometry:
    """The geometry of the default skeletons (``riderlive.skeleton``)."""
    from riderlive.skeleton.horse import HORSE_RIG
    from riderlive.skeleton.rider import BONES
    from riderlive.skeleton.rig import Rig as RigType

    return PartsGeometry.from_rigs(HORSE_RIG, RigType("rider", BONES, {}))
