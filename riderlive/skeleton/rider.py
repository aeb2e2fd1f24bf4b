"""The default rider skeleton (seated) and how the rider channels drive it.

The skeleton's origin is the seat point on the saddle (the horse's ``saddle`` bone);
axes as in :mod:`riderlive.skeleton.rig` (``+x`` forward, ``+y`` up, ``+z`` right).
The rest pose is the rider sitting on the standing horse: the rider channels given by
the default rules for :data:`~riderlive.skeleton.horse.HORSE_NEUTRAL` are the rig's
neutral values (the rules for an all-zero horse frame), and every channel acts as a delta from them.

Signs: ``*.rz`` > 0 bends forward (chest or nose down) for the back, waist, hips and
head, and lifts the toes for the feet; ``*.ry`` > 0 leans to the right for the back,
hips and head and turns the toes outward for the feet (mirrored); ``lower_back.rx`` > 0
twists to the left (counter-clockwise seen from above); the foot twist ``*.rx`` > 0
rolls the sole outward (mirrored). Wrist targets (``*_wrist.tz`` forward, ``*.ty`` up)
move with the seat (``cog.tx``, ``cog.ty``); foot targets (``*_foot.tx`` forward,
``*_foot.tz`` away from the belly) and knee poles (``*_knee.tz`` away from the belly,
``*_knee.ty`` up) stay with the saddle. ``rider_rig(tack=True)`` adds the rider parts
(``riderlive.rules.parts``) on top: ``*_rein.t*`` to the wrist targets (the hands on the
reins), ``*_arm.tz`` to the arm poles (elbows out, +), ``*_stirrup.t*`` to the foot
targets (the leathers); all in the seat frame, ``tz`` + to the right. Without them (or
with the plain rig) the limbs are Appendix B's.
"""

from __future__ import annotations

import functools

from riderlive.channels import HORSE_NAMES, RIDER_NAMES
from riderlive.skeleton.horse import HORSE_NEUTRAL
from riderlive.skeleton.quat import Vec3
from riderlive.skeleton.rig import Chain, Drive, Offset, Rig, X, Y, Z, bones_from_rows


def _side(prefix: str, rows: list[tuple[str, str, Vec3]]) -> list[tuple[str, str, Vec3]]:
    """Left (``lf_``, z < 0) or right (``rt_``, z > 0) copies of limb rows given for the left."""
    mirror = -1.0 if prefix == "rt_" else 1.0

    def named(n: str) -> str:
        return n.replace("lf_", prefix)

    return [(named(n), named(p), (o[0], o[1], o[2] * mirror + 0.0)) for n, p, o in rows]


_LEFT_LIMBS: list[tuple[str, str, Vec3]] = [
    ("lf_shoulder", "spine_f", (0.0, 0.06, -0.03)),
    ("lf_upperarm", "lf_shoulder", (0.0, 0.0, -0.16)),
    ("lf_forearm", "lf_upperarm", (-0.04, -0.27, -0.03)),
    ("lf_hand", "lf_forearm", (0.24, 0.04, 0.08)),
    ("lf_thigh", "hips", (0.0, -0.04, -0.10)),
    ("lf_shin", "lf_thigh", (0.28, -0.26, -0.22)),
    ("lf_foot", "lf_shin", (-0.12, -0.40, 0.02)),
    ("lf_toes", "lf_foot", (0.15, -0.04, 0.0)),
]

_ROWS: list[tuple[str, str | None, Vec3]] = [
    ("hips", None, (0.0, 0.10, 0.0)),
    ("lower_back", "hips", (0.0, 0.08, 0.0)),
    ("waist", "lower_back", (0.0, 0.10, 0.0)),
    ("spine_c", "waist", (0.0, 0.10, 0.0)),
    ("spine_d", "spine_c", (0.0, 0.10, 0.0)),
    ("spine_f", "spine_d", (0.0, 0.10, 0.0)),
    ("neck", "spine_f", (0.0, 0.12, 0.0)),
    ("head", "neck", (0.0, 0.10, 0.0)),
    *_side("lf_", _LEFT_LIMBS),
    *_side("rt_", _LEFT_LIMBS),
]


BONES = bones_from_rows(_ROWS)

HUMANOID: dict[str, tuple[str, str]] = {
    "hips": ("Hips", "hips"),
    "lower_back": ("Spine", "spine"),
    "waist": ("Chest", "chest"),
    "spine_f": ("UpperChest", "upperChest"),
    "neck": ("Neck", "neck"),
    "head": ("Head", "head"),
    **{
        f"{p}_{bone}": (f"{side}{unity}", f"{side.lower()}{unity}")
        for p, side in (("lf", "Left"), ("rt", "Right"))
        for bone, unity in (
            ("shoulder", "Shoulder"),
            ("upperarm", "UpperArm"),
            ("forearm", "LowerArm"),
            ("hand", "Hand"),
            ("thigh", "UpperLeg"),
            ("shin", "LowerLeg"),
            ("foot", "Foot"),
            ("toes", "Toes"),
        )
    },
}
"""Rider bone -> (Unity ``HumanBodyBones`` name, VRM humanoid bone name).

``spine_c`` and ``spine_d`` have no humanoid bone: they only carry squash and stretch
(translation), never a rotation, so dropping them loses no rotation.
"""


@functools.cache
def rider_neutral() -> dict[str, float]:
    """Rider channels of the default rules (metres) on the standing horse."""
    from riderlive.horse import DEFAULT_SCALE
    from riderlive.rules import RiderModel

    frame = [HORSE_NEUTRAL.get(name, 0.0) for name in HORSE_NAMES]
    values = RiderModel(scale=DEFAULT_SCALE).evaluate(frame)
    return {name: float(v) for name, v in zip(RIDER_NAMES, values, strict=True)}


def _limb_drives(tack: bool) -> tuple[tuple[Drive, ...], tuple[Chain, ...]]:
    rotations: list[Drive] = []
    chains: list[Chain] = []
    for p, out in (("lf", -1.0), ("rt", 1.0)):
        # Twist first, then side to side, then up/down (thesis rotate order X, Y, Z).
        rotations += [
            Drive(f"{p}_foot.rx", f"{p}_foot", X, out),
            Drive(f"{p}_foot.ry", f"{p}_foot", Y, -out),
            Drive(f"{p}_foot.rz", f"{p}_foot", Z),
        ]
        seat = (Offset("cog.tx", X), Offset("cog.ty", Y))
        rein = (Offset(f"{p}_rein.tx", X), Offset(f"{p}_rein.ty", Y), Offset(f"{p}_rein.tz", Z)) if tack else ()
        stirrup = (
            (Offset(f"{p}_stirrup.tx", X), Offset(f"{p}_stirrup.ty", Y), Offset(f"{p}_stirrup.tz", Z)) if tack else ()
        )
        elbow = (Offset(f"{p}_arm.tz", Z, out),) if tack else ()
        chains.append(
            Chain(
                f"{p}_upperarm",
                f"{p}_forearm",
                f"{p}_hand",
                frame=None,
                target=(Offset(f"{p}_wrist.tz", X), Offset(f"{p}_wrist.ty", Y), *seat, *rein),
                pole=(*seat, *elbow),
            )
        )
        chains.append(
            Chain(
                f"{p}_thigh",
                f"{p}_shin",
                f"{p}_foot",
                frame=None,
                target=(Offset(f"{p}_foot.tx", X), Offset(f"{p}_foot.tz", Z, out), *stirrup),
                pole=(Offset(f"{p}_knee.tz", Z, out), Offset(f"{p}_knee.ty", Y)),
            )
        )
    return tuple(rotations), tuple(chains)


@functools.cache
def rider_rig(tack: bool = False) -> Rig:
    """The rider rig (built once; its neutral values come from the default rules).

    ``tack``: the arm and leg IK also read the rider parts (``channels.RIDER_PARTS``:
    hands on the reins, elbows, feet in the stirrups); the bones are the same.
    """
    limb_rotations, chains = _limb_drives(tack)
    return Rig(
        name="rider_tack" if tack else "rider",
        bones=BONES,
        neutral=rider_neutral(),
        rotations=(
            Drive("hip.ry", "hips", X),
            Drive("hip.rz", "hips", Z, -1.0),
            Drive("lower_back.rx", "lower_back", Y),
            Drive("lower_back.ry", "lower_back", X),
            Drive("lower_back.rz", "lower_back", Z, -1.0),
            Drive("waist.rz", "waist", Z, -1.0),
            Drive("head.ry", "head", X),
            Drive("head.rz", "head", Z, -1.0),
            *limb_rotations,
        ),
        translations=(
            Drive("cog.tx", "hips", X),
            Drive("cog.ty", "hips", Y),
            Drive("spine_c.ty", "spine_c", Y),
            Drive("spine_d.ty", "spine_d", Y),
            Drive("spine_f.ty", "spine_f", Y),
            Drive("neck.ty", "neck", Y),
            Drive("head_a.ty", "head", Y),
        ),
        chains=chains,
    )
