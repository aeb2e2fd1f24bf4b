"""The channel vocabulary shared by every interface (files, websockets, servo maps).

Names follow the thesis rigs: ``node.attr`` where ``attr`` is ``tx ty tz`` (translate,
scene units of the thesis rig) or ``rx ry rz`` (rotate, degrees).

Axis convention of both rigs (thesis section 7): rotate Z bends front/back, rotate X
twists, rotate Y is side to side; translate X is forward/back, translate Y is up/down,
translate Z is side to side. The frame is right-handed like the thesis' Maya scene:
+X forward, +Y up, +Z to the horse's (and rider's) right; rotations follow the right
hand (+rz nose up, +rx rolls to the right, +ry turns left). A positive
``lower_back.rz`` leans the rider forward.
"""

from __future__ import annotations

import enum
import re
from dataclasses import dataclass
from functools import lru_cache


class Kind(enum.Enum):
    """What a channel's value measures, which decides its unit and its scaling."""

    ROTATION = "deg"
    TRANSLATION = "length"
    ATTRIBUTE = "unitless"


@dataclass(frozen=True, slots=True)
class Channel:
    """One named scalar signal."""

    name: str
    kind: Kind
    meaning: str

    @property
    def node(self) -> str:
        return self.name.split(".", 1)[0]

    @property
    def attr(self) -> str:
        return self.name.split(".", 1)[1]

    @property
    def unit(self) -> str:
        return self.kind.value


def _kind_of(attr: str) -> Kind:
    if attr in ("tx", "ty", "tz"):
        return Kind.TRANSLATION
    if attr in ("rx", "ry", "rz"):
        return Kind.ROTATION
    return Kind.ATTRIBUTE


def _table(rows: tuple[tuple[str, str], ...]) -> tuple[Channel, ...]:
    return tuple(Channel(name, _kind_of(name.split(".", 1)[1]), meaning) for name, meaning in rows)


_HOOF_ROWS: tuple[tuple[str, str], ...] = tuple(
    (f"{hoof}.{attr}", f"{label} hoof {what}")
    for hoof, label in (
        ("lfHoof", "left front"),
        ("rfHoof", "right front"),
        ("lbHoof", "left back"),
        ("rbHoof", "right back"),
    )
    for attr, what in (("tx", "forward/back"), ("ty", "height above ground"), ("tz", "side"))
)

HORSE: tuple[Channel, ...] = _table(
    (
        *_HOOF_ROWS,
        ("rearPivot.tx", "rear pivot (hips) forward/back"),
        ("rearPivot.ty", "rear pivot height"),
        ("rearPivot.tz", "rear pivot side"),
        ("rearPivot.rx", "rear pivot side to side (the horse's roll)"),
        ("rearPivot.ry", "rear pivot yaw (tail only)"),
        ("rearPivot.rz", "rear pivot up/down (the horse's pitch)"),
        ("backMid.rz", "mid-back pivot bend"),
        ("root.tx", "world position forward"),
        ("root.ty", "world position up"),
        ("root.tz", "world position side"),
        ("root.ry", "world heading"),
        ("horseNeck.rz", "neck up (+) / down at the withers, relative to the trunk (optional)"),
        ("horseNeck.ry", "neck to the horse's left (+) / right, relative to the trunk (optional)"),
        ("horseHead.rz", "head nose up (+) / down at the poll, relative to the neck (optional)"),
        ("ground.rz", "the ground's pitch under the horse, + rising ahead, degrees (optional; 0: flat)"),
        ("ground.ty", "the ground's height under the horse (optional; 0: flat)"),
    )
)
"""Every horse input channel, in the canonical column order of files and arrays.

The last five are optional in every input: a stream or file without them leaves
them 0. The neck and head (``docs/horse.md``) then rest on the trunk, and the ground
(``ground.*``, thesis section 10) is flat and level, which is how every horse moved
before they existed. On sloping ground ``rearPivot.rz`` is the trunk's pitch in the
world (the ground's pitch included); the hooves, ``rearPivot.t*`` and ``backMid.rz``
stay relative to the local ground (``riderlive.rules.terrain``)."""

HORSE_NECK_HEAD: tuple[str, ...] = ("horseNeck.rz", "horseNeck.ry", "horseHead.rz")
"""The optional horse channels of the neck and head: absent means 0, at rest on the trunk."""

HORSE_GROUND: tuple[str, ...] = ("ground.rz", "ground.ty")
"""The optional ground under the horse (pitch in degrees, + rising ahead; height): absent means 0, flat."""

HORSE_OPTIONAL: tuple[str, ...] = (*HORSE_NECK_HEAD, *HORSE_GROUND)
"""Every optional horse channel, the last ones of ``HORSE`` in this order."""

SADDLE: tuple[Channel, ...] = _table(
    (
        ("saddle.tx", "saddle point forward/back of where it sits standing square (m)"),
        ("saddle.ty", "saddle point up/down (m)"),
        ("saddle.tz", "saddle point side, + to the horse's right (m)"),
        ("saddle.rx", "saddle roll, + rolling to the right (deg)"),
        ("saddle.ry", "saddle yaw, + turning left (deg)"),
        ("saddle.rz", "saddle pitch, + nose up (deg)"),
    )
)
"""The saddle's pose (``riderlive.saddle``): a point on the horse's back, in the horse's
travelling frame (``root.*`` excluded), same axes and signs as ``rearPivot``; metres and
degrees. Computed from any horse frame, or the input of a saddle-only stream."""

RIDER: tuple[Channel, ...] = _table(
    (
        ("lower_back.rz", "Eq. 1: lower back forward (+) / back"),
        ("lower_back.ry", "Eq. 2: lower back side to side"),
        ("lower_back.rx", "Eq. 3: lower back twist"),
        ("waist.rz", "Eq. 4: waist forward/back"),
        ("hip.rz", "Eq. 5: hips forward/back"),
        ("hip.ry", "Eq. 6: hips side to side"),
        ("cog.ty", "Eq. 7: lift in the seat"),
        ("cog.tx", "Eq. 8: shift in the seat"),
        ("spine_c.ty", "Eq. 9: squash and stretch"),
        ("spine_d.ty", "Eq. 9: squash and stretch"),
        ("spine_f.ty", "Eq. 9: squash and stretch"),
        ("neck.ty", "Eq. 9: squash and stretch"),
        ("head_a.ty", "Eq. 9: squash and stretch"),
        ("head.rz", "Eq. 10: head forward/back"),
        ("head.ry", "Eq. 11: head side to side"),
        ("lf_wrist.tz", "Eq. 12: left wrist forward/back"),
        ("rt_wrist.tz", "Eq. 12: right wrist forward/back"),
        ("lf_wrist.ty", "Eq. 13: left wrist up/down"),
        ("rt_wrist.ty", "Eq. 13: right wrist up/down"),
        ("lf_foot.tx", "Eq. 14: left foot forward/back"),
        ("rt_foot.tx", "Eq. 14: right foot forward/back"),
        ("lf_foot.rz", "Eq. 15: left foot up/down"),
        ("rt_foot.rz", "Eq. 15: right foot up/down"),
        ("lf_foot.ry", "Eq. 16: left foot side to side"),
        ("rt_foot.ry", "Eq. 16: right foot side to side"),
        ("lf_foot.rx", "Eq. 16 family: left foot twist"),
        ("rt_foot.rx", "Eq. 16 family: right foot twist"),
        ("lf_foot.tz", "Eq. 17: left foot toward/away from the belly"),
        ("rt_foot.tz", "Eq. 17: right foot toward/away from the belly"),
        ("lf_knee.tz", "Eq. 18: left knee toward/away from the belly"),
        ("rt_knee.tz", "Eq. 18: right knee toward/away from the belly"),
        ("lf_knee.ty", "left knee lift"),
        ("rt_knee.ty", "right knee lift"),
        ("hair.up", "hair up/down attribute"),
        ("hair.side", "hair side to side attribute"),
        ("cloth.up", "cloth up/down attribute"),
        ("cloth.side", "cloth side to side attribute"),
    )
)
"""Every rider output channel of the rules, in canonical order."""

RIDER_PARTS: tuple[Channel, ...] = _table(
    (
        *(
            (f"{side}_rein.{attr}", f"{label} hand on the rein (5.1): {what} added to the wrist target, seat frame")
            for side, label in (("lf", "left"), ("rt", "right"))
            for attr, what in (("tx", "forward"), ("ty", "up"), ("tz", "to the right"))
        ),
        ("lf_arm.tz", "left elbow out (+) from / in (-) to the body (5.3)"),
        ("rt_arm.tz", "right elbow out (+) from / in (-) to the body (5.3)"),
        *(
            (f"{side}_stirrup.{attr}", f"{label} foot held by its stirrup leather: {what} added to the foot target")
            for side, label in (("lf", "left"), ("rt", "right"))
            for attr, what in (("tx", "forward"), ("ty", "up"), ("tz", "to the right"))
        ),
        ("reins.slip", "how far the reins outran the hands at full reach, fraction of the rein (0: in hand)"),
    )
)
"""The rider parts Appendix B leaves out (``riderlive.rules.parts``): published after the
rider channels (as extra channels of the output), posing the skeleton's arms and legs."""

HORSE_NAMES: tuple[str, ...] = tuple(c.name for c in HORSE)
RIDER_NAMES: tuple[str, ...] = tuple(c.name for c in RIDER)
HORSE_INDEX: dict[str, int] = {n: i for i, n in enumerate(HORSE_NAMES)}
RIDER_INDEX: dict[str, int] = {n: i for i, n in enumerate(RIDER_NAMES)}
SADDLE_NAMES: tuple[str, ...] = tuple(c.name for c in SADDLE)
SADDLE_INDEX: dict[str, int] = {n: i for i, n in enumerate(SADDLE_NAMES)}
RIDER_PART_NAMES: tuple[str, ...] = tuple(c.name for c in RIDER_PARTS)
BY_NAME: dict[str, Channel] = {c.name: c for c in HORSE + RIDER + SADDLE + RIDER_PARTS}

AXIS_CONVENTION: dict[str, str] = {
    "rz": "bend front/back",
    "rx": "twist",
    "ry": "side to side",
    "tx": "forward/back",
    "ty": "up/down",
    "tz": "side to side",
}
"""The thesis rigs' axis convention (section 7), as published in hellos and docs."""


BONE_CHANNEL = re.compile(
    r"(?P<node>(?:tail|braid|lf_cloth|rt_cloth)_\d{2})\.(?P<attr>t[xyz]|r[xyz]|q[xyzw]|fan)|tail_ref\.t[xyz]"
)
"""Simulated bone chains (``riderlive.physics``): ``tail_NN`` / ``braid_NN`` / ``lf_cloth_NN`` /
``rt_cloth_NN`` (the rider's coat-skirt flaps) with world position ``t*`` (m), local
rotation ``r*`` (deg) and ``q*`` (unit quaternion, x y z w),
``fan`` (sub-chain spread, m); ``tail_ref`` is the reference tail's mean tip (m)."""


PLATFORM_CHANNEL = re.compile(r"platform\.(?:t[xyz]|r[xyz]|a[1-9])")
"""Motion platform tracks (``riderlive.platform``): the pose relative to home ``t*`` (m), ``r*``
(deg), and actuator positions ``a1`` ... (m of extension, or deg of crank for a rotary platform)."""


class UnknownChannelError(KeyError):
    """A channel name that is not part of the vocabulary."""


@lru_cache(maxsize=4096)
def _bone_channel(name: str) -> Channel | None:
    if PLATFORM_CHANNEL.fullmatch(name):
        return Channel(name, _kind_of(name.split(".", 1)[1]), "motion platform track")
    if not BONE_CHANNEL.fullmatch(name):
        return None
    attr = name.split(".", 1)[1]
    kind = Kind.TRANSLATION if attr == "fan" else _kind_of(attr)
    return Channel(name, kind, "simulated bone chain")


def lookup(name: str) -> Channel:
    """Return the channel called ``name`` or raise :class:`UnknownChannelError`."""
    channel = BY_NAME.get(name) or _bone_channel(name)
    if channel is None:
        raise UnknownChannelError(name)
    return channel


def is_known(name: str) -> bool:
    """Whether ``name`` is a horse, rider, rider-part, saddle or simulated-bone channel."""
    return name in BY_NAME or _bone_channel(name) is not None
