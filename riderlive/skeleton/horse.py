"""The default horse skeleton and how the horse channels drive it.

Channels are metres and degrees in the horse's body frame (origin on the ground under
the middle of the body, ``+x`` forward, ``+y`` up, ``+z`` right). The hoof channels
are hoof positions relative to the body: ``tx`` forward from the middle, ``ty``
height above the ground, ``tz`` sideways from the leg's rest line; the rear pivot's
``tx ty tz`` are its position (``ty`` its height above the ground). The rear pivot turns
by ``Ry(ry) Rz(rz) Rx(rx)`` (roll first, yaw last), like ``riderlive.physics``' frame
of the hindquarters; the tail root sits where its dock is. :data:`HORSE_NEUTRAL` is the standing horse,
whose pose is the rest pose. ``rearPivot.rz`` > 0 lifts the front (pitch up),
``rearPivot.rx`` > 0 rolls the right side down, ``root.ry`` > 0 turns left.
"""

from __future__ import annotations

from riderlive.skeleton.quat import Vec3
from riderlive.skeleton.rig import Bone, Chain, Drive, Offset, Rig, X, Y, Z

_SIDE = 0.2
"""Half the distance between a left and a right leg, metres."""


def _leg(hoof: str, parent: str, right: bool, knee: Vec3, fetlock: Vec3) -> list[tuple[str, str, Vec3]]:
    side = _SIDE if right else -_SIDE
    middle = "Knee" if hoof[1] == "f" else "Hock"
    return [
        (f"{hoof}Leg", parent, (0.0, 0.0, side)),
        (f"{hoof}{middle}", f"{hoof}Leg", knee),
        (f"{hoof}Fetlock", f"{hoof}{middle}", fetlock),
        (f"{hoof}Hoof", f"{hoof}Fetlock", (0.02, -0.18, 0.0)),
    ]


_FRONT_KNEE: Vec3 = (0.10, -0.62, 0.0)
_FRONT_CANNON: Vec3 = (-0.07, -0.34, 0.0)
_HIND_HOCK: Vec3 = (-0.17, -0.50, 0.0)
_HIND_CANNON: Vec3 = (0.05, -0.32, 0.0)

_ROWS: list[tuple[str, str | None, Vec3]] = [
    ("root", None, (0.0, 0.0, 0.0)),
    ("rearPivot", "root", (0.0, 1.0, 0.0)),
    ("backMid", "rearPivot", (0.0, 0.28, 0.0)),
    ("saddle", "backMid", (0.1, 0.18, 0.0)),
    ("shoulders", "backMid", (0.55, -0.14, 0.0)),
    ("neck", "shoulders", (0.25, 0.2, 0.0)),
    ("head", "neck", (0.35, 0.42, 0.0)),
    ("muzzle", "head", (0.2, -0.45, 0.0)),
    ("tailRoot", "rearPivot", (-0.5, 0.42, 0.0)),
    *_leg("lf", "shoulders", False, _FRONT_KNEE, _FRONT_CANNON),
    *_leg("rf", "shoulders", True, _FRONT_KNEE, _FRONT_CANNON),
    ("hips", "rearPivot", (-0.5, 0.0, 0.0)),
    *_leg("lb", "hips", False, _HIND_HOCK, _HIND_CANNON),
    *_leg("rb", "hips", True, _HIND_HOCK, _HIND_CANNON),
]


def _bones() -> tuple[Bone, ...]:
    index: dict[str, int] = {}
    bones: list[Bone] = []
    for name, parent, offset in _ROWS:
        bones.append(Bone(name, -1 if parent is None else index[parent], offset))
        index[name] = len(bones) - 1
    return tuple(bones)


BONES = _bones()
_REST = {b.name: b for b in BONES}


def _rest_x(name: str) -> float:
    """Rest forward position of a joint relative to the body middle, metres."""
    x = 0.0
    i = next(k for k, b in enumerate(BONES) if b.name == name)
    while i >= 0:
        x += BONES[i].offset[0]
        i = BONES[i].parent
    return x


HOOVES: tuple[str, ...] = ("lf", "rf", "lb", "rb")

HORSE_NEUTRAL: dict[str, float] = {
    **{f"{h}Hoof.tx": round(_rest_x(f"{h}Hoof"), 9) for h in HOOVES},
    "rearPivot.ty": _REST["rearPivot"].offset[1],
}
"""Horse channel values of the standing horse (the rest pose); other channels are 0."""

HORSE_RIG = Rig(
    name="horse",
    bones=BONES,
    neutral=HORSE_NEUTRAL,
    rotations=(
        Drive("root.ry", "root", Y),
        Drive("rearPivot.rx", "rearPivot", X),
        Drive("rearPivot.rz", "rearPivot", Z),
        Drive("rearPivot.ry", "rearPivot", Y),
        Drive("backMid.rz", "backMid", Z),
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
