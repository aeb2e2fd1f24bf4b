"""The rider parts the rules of Appendix B leave out: hands on the reins, arms, feet in the stirrups.

Each part turns the rules' output (and the horse's optional neck and head channels)
into channels that the rider skeleton adds to its arm and leg IK targets
(``riderlive.skeleton.rider``), so the wrist and foot rules stay exactly as they are
and act as offsets on top:

- **reins** (section 5.1: "her hands ... mostly stay in position" near the neck, close to
  it without resting on it): each hand keeps its rest distance to its bit ring (the
  horse skeleton's ``leftRein`` / ``rightRein``, at the corners of the mouth, moved by
  ``horseNeck.*`` and ``horseHead.rz``) along the line from the ring to where the seat
  (``cog.*``) carries the hand. ``*_rein.t*`` is that grip minus the seat-carried hand.
  A grip beyond the arm's reach (``reins.reach`` of the arm's length from the shoulder,
  the trunk's forward lean taken into account) stays at full reach; ``reins.slip`` says
  by how much the reins outran the hands (a fraction of the rein), 0 when in hand.
- **arms** (section 5.3: "arms are brought slightly into her body as she rises in the
  air and slightly out ... as she and the horse fall back"): ``*_arm.tz`` moves each
  elbow (the arm IK's pole) in by ``arms.in_gain`` times the lift (Eq. 7), out as the
  lift falls.
- **stirrups**: the ball of each foot stands in its iron, which hangs from its bar on a
  leather of fixed length (the horse skeleton's ``leftStirrup`` offset from
  ``leftStirrupBar``, times ``stirrups.leather_scale``). Where Eq. 14 and 17 move the
  foot further from the bar than that, ``*_stirrup.t*`` brings it back onto the
  leather's sphere (the iron swings up as the foot swings out), in the seat frame
  (``tz`` + to the rider's right). The foot's own rotations (Eq. 15-16) are left out of
  the ball's position: they move it by a few centimetres.

Frames and units: the seat frame is the rider skeleton's (origin on the horse's
``saddle`` bone, +x forward, +y up, +z right). The parts read the rider channels as
published (after the animator layer, smoothing and blends: what the skeleton is posed
from) and the horse frame, both in service units, and work in the skeletons' metres
(``metres_per_unit`` converts). The rider skeleton poses from deltas to its
``neutral`` values, so the parts measure the rider channels from the same values.

A skeleton without rein or stirrup bones, or with absurd lengths, switches that part off
(its channels stay 0: the hands and feet of Appendix B) and says why in
:attr:`PartsGeometry.notes`. The same source runs on floats (the live tick) and on NumPy
arrays (takes), as :mod:`riderlive.rules.kuhnel2003` does.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np

from riderlive.channels import RIDER_INDEX, RIDER_PART_NAMES
from riderlive.rules.params import RuleParams
from riderlive.skeleton.quat import Vec3, add, norm, sub
from riderlive.skeleton.rig import Bone, Rig

PART_INPUTS: tuple[str, ...] = ("horseNeck.rz", "horseNeck.ry", "horseHead.rz")
"""The horse channels the parts read (degrees), besides the rules' output."""
PART_OUTPUTS: tuple[str, ...] = RIDER_PART_NAMES
"""What :func:`make_parts` returns, in this order (``channels.RIDER_PARTS``)."""
REIN_LENGTH_RANGE = (0.2, 3.0)
LEATHER_LENGTH_RANGE = (0.2, 1.5)
ARM_LENGTH_RANGE = (0.2, 1.5)
"""Skeleton lengths (m) the parts accept; outside, the part is off (a note says so)."""

PartsFunction = Callable[..., tuple[Any, ...]]


@dataclass(frozen=True, slots=True)
class PartOps:
    """The primitives whose float and array forms differ."""

    sqrt: Callable[[Any], Any]
    sin: Callable[[Any], Any]
    cos: Callable[[Any], Any]
    maximum: Callable[[Any, Any], Any]


SCALAR = PartOps(math.sqrt, math.sin, math.cos, max)
ARRAY = PartOps(np.sqrt, np.sin, np.cos, np.maximum)


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
            reins = [
                norm(sub(hand, sub(h_rest[n], seat))) for hand, n in zip(hands, ("leftRein", "rightRein"), strict=True)
            ]
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


def make_parts(
    p: RuleParams,
    geometry: PartsGeometry,
    ops: PartOps,
    neutral: Sequence[float],
    metres_per_unit: float = 1.0,
) -> PartsFunction:
    """``parts(neck_rz, neck_ry, head_rz, rider) -> tuple`` in :data:`PART_OUTPUTS` order.

    ``rider`` is a rider frame (``channels.RIDER`` order, service units), ``neutral``
    the rider skeleton's neutral frame (metres: ``rider_rig().neutral``); angles in
    degrees; the outputs are in service units (``reins.slip`` a plain fraction).
    Constants are bound to local names first (the live path reads closure constants,
    several times faster than attribute look-ups).
    """
    sqrt, sin, cos, maximum = ops.sqrt, ops.sin, ops.cos, ops.maximum
    m = metres_per_unit
    if not (math.isfinite(m) and m > 0.0):
        raise ValueError(f"metres_per_unit must be a finite number > 0, got {m!r}")
    per_unit = 1.0 / m
    i_lift, i_shift = RIDER_INDEX["cog.ty"], RIDER_INDEX["cog.tx"]
    i_back, i_waist, i_hip = RIDER_INDEX["lower_back.rz"], RIDER_INDEX["waist.rz"], RIDER_INDEX["hip.rz"]
    i_lwx, i_lwy = RIDER_INDEX["lf_wrist.tz"], RIDER_INDEX["lf_wrist.ty"]
    i_rwx, i_rwy = RIDER_INDEX["rt_wrist.tz"], RIDER_INDEX["rt_wrist.ty"]
    i_lfx, i_lfz = RIDER_INDEX["lf_foot.tx"], RIDER_INDEX["lf_foot.tz"]
    i_rfx, i_rfz = RIDER_INDEX["rt_foot.tx"], RIDER_INDEX["rt_foot.tz"]
    n_lift, n_shift = neutral[i_lift], neutral[i_shift]
    n_lean = neutral[i_back] + neutral[i_waist] + neutral[i_hip]
    n_lwx, n_lwy, n_rwx, n_rwy = neutral[i_lwx], neutral[i_lwy], neutral[i_rwx], neutral[i_rwy]
    n_lfx, n_lfz, n_rfx, n_rfz = neutral[i_lfx], neutral[i_lfz], neutral[i_rfx], neutral[i_rfz]
    arm_gain = -p.arms.in_gain
    rad = math.pi / 180.0
    tiny = 1e-12

    reins_on = geometry.has_reins and p.reins.weight > 0.0
    rein_w = p.reins.weight
    assert geometry.neck is not None or not reins_on
    nx, ny, nz = geometry.neck or (0.0, 0.0, 0.0)
    px, py, _ = geometry.poll
    (gx, gy, lgz), (_, _, rgz) = geometry.rings[0], geometry.rings[1]
    (lhx, lhy, lhz), (rhx, rhy, rhz) = geometry.hands[0], geometry.hands[1]
    (sx0, sy0, lsz), (_, _, rsz) = geometry.shoulders[0], geometry.shoulders[1]
    ox, oy, _ = geometry.lean_pivot
    sx0, sy0 = sx0 - ox, sy0 - oy
    reach = p.reins.reach * geometry.arm_length
    # Rest rein lengths: each hand to its ring with the neck and head at rest.
    rest_bit = [add((nx, ny, nz), (px + gx, py + gy, z)) for z in (lgz, rgz)]
    l_rein = norm(sub((lhx, lhy, lhz), rest_bit[0])) * p.reins.length_scale if reins_on else 1.0
    r_rein = norm(sub((rhx, rhy, rhz), rest_bit[1])) * p.reins.length_scale if reins_on else 1.0

    feet_on = geometry.has_stirrups and p.stirrups.weight > 0.0
    foot_w = p.stirrups.weight
    ankles = geometry.ankles or ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    (lax, lay, laz), (rax, ray, raz) = ankles[0], ankles[1]
    (lcx, lcy, lcz), (rcx, rcy, rcz) = geometry.centres[0], geometry.centres[1]
    l_leather = geometry.leathers[0] * p.stirrups.leather_scale
    r_leather = geometry.leathers[1] * p.stirrups.leather_scale
    l_dy, r_dy = lay - lcy, ray - rcy  # the legs' targets keep their rest height (Appendix B moves x and z)
    feet_on = feet_on and l_dy < 0.0 and r_dy < 0.0  # from_rigs refuses a bar below its ankle

    def hand(  # noqa: PLR0917 (the live path: positional floats, no packing)
        bx: Any, by: Any, bz: Any, wx: Any, wy: Any, wz: Any, qx0: Any, qy0: Any, qz: Any, rein: float
    ) -> Any:
        """One hand's grip on its rein minus the seat-carried hand ``w`` (service units), and the rein's slip."""
        ex, ey, ez = wx - bx, wy - by, wz - bz
        k = rein / maximum(sqrt(ex * ex + ey * ey + ez * ez), tiny)
        gx_, gy_, gz_ = bx + ex * k, by + ey * k, bz + ez * k
        qx, qy, qz = gx_ - qx0, gy_ - qy0, gz_ - qz  # to the hand from ``q0``: the shoulder less the wrist rules
        q = sqrt(qx * qx + qy * qy + qz * qz)
        over = maximum(q - reach, 0.0)
        f = over / maximum(q, tiny)
        u = per_unit
        return ((gx_ - qx * f - wx) * u, (gy_ - qy * f - wy) * u, (gz_ - qz * f - wz) * u, over / rein)

    def foot(tx: Any, tz: Any, cx: float, dy: float, cz: float, leather: float) -> Any:  # noqa: PLR0917
        """The correction that puts the ankle target ``(tx, rest, tz)`` within ``leather`` of its centre."""
        dx, dz = tx - cx, tz - cz
        d = sqrt(dx * dx + dy * dy + dz * dz)  # > 0: the centre is above the ankle (dy)
        f = maximum(d - leather, 0.0) / d * foot_w * per_unit
        return (-dx * f, -dy * f, -dz * f)

    zero3 = (0.0, 0.0, 0.0)

    def parts(neck_rz: Any, neck_ry: Any, head_rz: Any, r: Sequence[Any]) -> tuple[Any, ...]:
        lift = r[i_lift] * m - n_lift  # metres from here on
        arm = lift * arm_gain * per_unit
        if reins_on:
            shift = r[i_shift] * m - n_shift
            a, b, c = head_rz * rad, neck_rz * rad, neck_ry * rad
            ch, sh, cn, sn, cy, sy = cos(a), sin(a), cos(b), sin(b), cos(c), sin(c)
            wx = px + gx * ch - gy * sh  # the rings in the neck's frame (they differ only in z)
            wy = py + gx * sh + gy * ch
            ux = wx * cn - wy * sn  # turned up or down by the neck, then sideways
            bx, by, bz = nx + ux * cy, ny + wx * sn + wy * cn, nz - ux * sy
            t = (r[i_back] + r[i_waist] + r[i_hip] - n_lean) * rad  # the trunk's forward lean
            ct, st = cos(t), sin(t)
            qx0 = ox + sx0 * ct + sy0 * st + shift
            qy0 = oy - sx0 * st + sy0 * ct + lift
            left = hand(
                bx + lgz * sy,
                by,
                bz + lgz * cy,
                lhx + shift,
                lhy + lift,
                lhz,
                qx0 - (r[i_lwx] * m - n_lwx),
                qy0 - (r[i_lwy] * m - n_lwy),
                lsz,
                l_rein,
            )
            right = hand(
                bx + rgz * sy,
                by,
                bz + rgz * cy,
                rhx + shift,
                rhy + lift,
                rhz,
                qx0 - (r[i_rwx] * m - n_rwx),
                qy0 - (r[i_rwy] * m - n_rwy),
                rsz,
                r_rein,
            )
            slip = maximum(left[3], right[3])
            if rein_w != 1.0:
                left = (left[0] * rein_w, left[1] * rein_w, left[2] * rein_w)
                right = (right[0] * rein_w, right[1] * rein_w, right[2] * rein_w)
        else:
            left = right = zero3
            slip = 0.0 * arm
        if feet_on:
            lf = foot(lax + r[i_lfx] * m - n_lfx, laz - (r[i_lfz] * m - n_lfz), lcx, l_dy, lcz, l_leather)
            rf = foot(rax + r[i_rfx] * m - n_rfx, raz + (r[i_rfz] * m - n_rfz), rcx, r_dy, rcz, r_leather)
        else:
            lf = rf = zero3
        return (
            left[0],
            left[1],
            left[2],
            right[0],
            right[1],
            right[2],
            arm,
            arm,
            lf[0],
            lf[1],
            lf[2],
            rf[0],
            rf[1],
            rf[2],
            slip,
        )

    return parts


@dataclass(frozen=True)
class RiderParts:
    """The parts of a preset on one skeleton pair, for rider frames in service units.

    ``metres_per_unit``: the service length unit in metres (``length_scale / 25``).
    """

    params: RuleParams
    metres_per_unit: float = 1.0
    geometry: PartsGeometry | None = None
    """None: :func:`default_geometry`."""

    def __post_init__(self) -> None:
        from riderlive.channels import HORSE_INDEX, RIDER_NAMES
        from riderlive.skeleton.rider import rider_neutral

        geometry = self.geometry or default_geometry()
        neutral_map = rider_neutral()
        neutral = [neutral_map.get(n, 0.0) for n in RIDER_NAMES]
        m = self.metres_per_unit
        object.__setattr__(self, "_one", make_parts(self.params, geometry, SCALAR, neutral, m))
        object.__setattr__(self, "_many", make_parts(self.params, geometry, ARRAY, neutral, m))
        object.__setattr__(self, "_columns", tuple(HORSE_INDEX[n] for n in PART_INPUTS))
        object.__setattr__(self, "notes", geometry.notes)

    def evaluate(self, horse: Sequence[float], rider: Sequence[float]) -> list[float]:
        """One frame: ``horse`` in ``channels.HORSE`` order, ``rider`` in ``channels.RIDER`` order."""
        i, j, k = self._columns  # type: ignore[attr-defined]
        return list(self._one(horse[i], horse[j], horse[k], rider))  # type: ignore[attr-defined]

    def evaluate_batch(self, horse: Any, rider: Any) -> Any:
        """N frames: ``horse`` (N, len(HORSE)), ``rider`` (N, len(RIDER)); returns (N, len(PART_OUTPUTS))."""
        horse = np.asarray(horse, dtype=np.float64)
        rider = np.asarray(rider, dtype=np.float64)
        i, j, k = self._columns  # type: ignore[attr-defined]
        values = self._many(horse[:, i], horse[:, j], horse[:, k], tuple(rider.T))  # type: ignore[attr-defined]
        out = np.empty((len(horse), len(PART_OUTPUTS)))
        for c, v in enumerate(values):
            out[:, c] = v
        return out
