"""The default horse skeleton and how the horse channels drive it.

Channels are metres and degrees, as :mod:`riderlive.horse` emits them: every channel is
0 for the square-standing horse, which is this skeleton's rest pose. Hoof ``tx`` is
forward of the hoof's standing spot, ``ty`` its height above the ground, ``tz`` to the
horse's right; ``rearPivot.t*`` displace the hips from standing (``tz`` + right);
``rearPivot.rz`` > 0 lifts the front (pitch up), ``rearPivot.rx`` > 0 rolls to the right
(right side down), ``root.ry`` > 0 turns left. The rear pivot turns by
``Ry(ry) Rz(rz) Rx(rx)`` (roll first, yaw last) about the hips, where
``riderlive.physics`` has it (``pivot_rest``); the tail root is its dock. The skeleton's axes are those of
:mod:`riderlive.skeleton.rig` and of the channels (right-handed, ``+z`` the horse's
right), so every channel drives its axis with a positive sign. The neck turns at the
withers by ``Ry(horseNeck.ry) Rz(horseNeck.rz)``, the head at the poll by
``Rz(horseHead.rz)``; both are optional channels (0: at rest on the trunk).

On sloping ground (the optional ``ground.rz``, thesis section 10) the root turns by
``Ry(root.ry) Rz(ground.rz)``: the legs' targets (the hooves, in the root's frame) and
the hips' offsets lie along the local ground, as the channels measure them. The rear
pivot turns by ``Rz(-ground.rz)`` on top of its own drives, so its world pitch is
``rearPivot.rz``, the trunk's pitch in the world (the ground's included).
"""

from __future__ import annotations

from riderlive.skeleton.quat import Vec3
from riderlive.skeleton.rig import Chain, Drive, Offset, Rig, X, Y, Z, bones_from_rows

_SIDE = 0.2
"""Half the distance between a left and a right leg, metres."""


def _leg(hoof: str, parent: str, right: bool, knee: Vec3, fetlock: Vec3) -> list[tuple[str, str, Vec3]]:
    side = _SIDE if right else -_SIDE
    middle = "Knee" if hoof[1] == "f" else "Hock"
    return [
        (f"{hoof}Leg", parent, (0.0, _LEG_ROOT_HEIGHT, side)),
        (f"{hoof}{middle}", f"{hoof}Leg", knee),
        (f"{hoof}Fetlock", f"{hoof}{middle}", fetlock),
        (f"{hoof}Hoof", f"{hoof}Fetlock", (0.02, -0.18, 0.0)),
    ]


_LEG_ROOT_HEIGHT = 0.3
"""The legs hang from the top of the shoulder blade and the croup, above the joints."""
_FRONT_KNEE: Vec3 = (0.12, -0.92, 0.0)
_FRONT_CANNON: Vec3 = (-0.09, -0.34, 0.0)
_HIND_HOCK: Vec3 = (-0.12, -0.85, 0.0)
_HIND_CANNON: Vec3 = (0.05, -0.32, 0.0)

_ROWS: list[tuple[str, str | None, Vec3]] = [
    ("root", None, (0.0, 0.0, 0.0)),
    ("rearPivot", "root", (-0.55, 1.05, 0.0)),
    ("backMid", "rearPivot", (0.55, 0.23, 0.0)),
    ("saddle", "backMid", (0.05, 0.18, 0.0)),
    ("shoulders", "backMid", (0.55, -0.14, 0.0)),
    ("neck", "shoulders", (0.25, 0.2, 0.0)),
    ("head", "neck", (0.35, 0.42, 0.0)),
    ("muzzle", "head", (0.2, -0.45, 0.0)),
    ("tailRoot", "rearPivot", (-0.5, 0.42, 0.0)),
    *_leg("lf", "shoulders", False, _FRONT_KNEE, _FRONT_CANNON),
    *_leg("rf", "shoulders", True, _FRONT_KNEE, _FRONT_CANNON),
    ("hips", "rearPivot", (-0.05, 0.0, 0.0)),
    *_leg("lb", "hips", False, _HIND_HOCK, _HIND_CANNON),
    *_leg("rb", "hips", True, _HIND_HOCK, _HIND_CANNON),
    # Tack (appended: bone indices above are unchanged). The reins end at the bit rings
    # at the corners of the mouth; each stirrup iron hangs from its bar on the saddle
    # tree, its leather (the iron's offset) long enough for the rider's rest pose, whose
    # ball of the foot (``lf_toes``) sits in the iron.
    ("leftRein", "head", (0.15, -0.34, -0.06)),
    ("rightRein", "head", (0.15, -0.34, 0.06)),
    ("leftStirrupBar", "saddle", (0.25, -0.05, -0.17)),
    ("leftStirrup", "leftStirrupBar", (0.06, -0.59, -0.13)),
    ("rightStirrupBar", "saddle", (0.25, -0.05, 0.17)),
    ("rightStirrup", "rightStirrupBar", (0.06, -0.59, 0.13)),
]


BONES = bones_from_rows(_ROWS)


HOOVES: tuple[str, ...] = ("lf", "rf", "lb", "rb")

HORSE_NEUTRAL: dict[str, float] = {}
"""Horse channel values of the standing horse (the rest pose): all 0."""

HORSE_RIG = Rig(
    name="horse",
    bones=BONES,
    neutral=HORSE_NEUTRAL,
    rotations=(
        Drive("ground.rz", "root", Z),  # first: the root turns by Ry(root.ry) Rz(ground.rz)
        Drive("root.ry", "root", Y),
        Drive("rearPivot.rx", "rearPivot", X),
        Drive("rearPivot.rz", "rearPivot", Z),
        Drive("rearPivot.ry", "rearPivot", Y),
        Drive("ground.rz", "rearPivot", Z, -1.0),  # last: rearPivot.rz is the trunk's world pitch
        Drive("backMid.rz", "backMid", Z),
        Drive("horseNeck.rz", "neck", Z),
        Drive("horseNeck.ry", "neck", Y),
        Drive("horseHead.rz", "head", Z),
    ),
    translations=(
        Drive("root.tx", "root", X),
        Drive("root.ty", "root", Y),
        Drive("root.tz", "root", Z),
        Drive("rearPivot.tx", "rearPivot", X),
        Drive("rearPivot.ty", "rearPivot", Y),
        Drive("rearPivot.tz", "rearPivot", Z),
    ),
    chains=tuple(
        Chain(
            upper=f"{h}Leg",
            lower=f"{h}{'Knee' if h[1] == 'f' else 'Hock'}",
            end=f"{h}Fetlock",
            frame="root",
            target=(Offset(f"{h}Hoof.tx", X), Offset(f"{h}Hoof.ty", Y), Offset(f"{h}Hoof.tz", Z)),
        )
        for h in HOOVES
    ),
)
