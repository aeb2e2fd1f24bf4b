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
:attr:`PartsGeometry.notes` (:mod:`riderlive.rules.parts_geometry`).

One source (:func:`make_parts`) runs on NumPy arrays (takes), on Python floats, and
compiled by numba (:func:`compiled_parts`: the live tick, ~1 us a frame against ~6 us
interpreted; ``bench/bench_parts.py``). The skeletons' geometry is bound into it; the
preset's values and the length unit come in as an argument (:func:`parts_knobs`), so a
live parameter change never compiles. The tick compiles or loads it before its first
deadline (:meth:`RiderParts.warm`).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cache
from operator import itemgetter
from typing import Any, cast

import numpy as np

from riderlive.channels import RIDER_INDEX, RIDER_PART_NAMES
from riderlive.rules.params import RuleParams
from riderlive.rules.parts_geometry import PartsGeometry, default_geometry

log = logging.getLogger(__name__)

PART_INPUTS: tuple[str, ...] = ("horseNeck.rz", "horseNeck.ry", "horseHead.rz")
"""The horse channels the parts read (degrees), besides the rules' output."""
PART_OUTPUTS: tuple[str, ...] = RIDER_PART_NAMES
"""What :func:`make_parts` returns, in this order (``channels.RIDER_PARTS``)."""

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


PART_RIDER_INPUTS: tuple[str, ...] = (
    "cog.ty",
    "cog.tx",
    "lower_back.rz",
    "waist.rz",
    "hip.rz",
    "lf_wrist.tz",
    "lf_wrist.ty",
    "rt_wrist.tz",
    "rt_wrist.ty",
    "lf_foot.tx",
    "lf_foot.tz",
    "rt_foot.tx",
    "rt_foot.tz",
)
"""The rider channels the parts read, in the order :func:`make_parts`' function takes them."""

KNOBS: tuple[str, ...] = (
    "metres_per_unit",
    "units_per_metre",
    "arm_gain",
    "rein_weight",
    "reach",
    "left_rein",
    "right_rein",
    "foot_weight",
    "left_leather",
    "right_leather",
)
"""What a preset and the length unit set, in the order of :func:`parts_knobs` (metres unless said)."""
_M, _PER_UNIT, _ARM_GAIN, _REIN_W, _REACH, _L_REIN, _R_REIN, _FOOT_W, _L_LEATHER, _R_LEATHER = range(len(KNOBS))


def parts_knobs(p: RuleParams, geometry: PartsGeometry, metres_per_unit: float = 1.0) -> tuple[float, ...]:
    """The values in :data:`KNOBS` order for preset ``p`` on ``geometry`` in a unit of ``metres_per_unit``.

    A parameter change changes only these (not the compiled function: :func:`make_parts`).
    Rein lengths are the skeletons' (``geometry.reins``) times ``reins.length_scale``;
    leathers the skeleton's, times ``stirrups.leather_scale``.
    """
    m = metres_per_unit
    if not (math.isfinite(m) and m > 0.0):
        raise ValueError(f"metres_per_unit must be a finite number > 0, got {m!r}")
    reins = geometry.reins if geometry.has_reins else (1.0, 1.0)  # never divided by 0 when the reins are off
    return (
        m,
        1.0 / m,
        -p.arms.in_gain,
        p.reins.weight,
        p.reins.reach * geometry.arm_length,
        reins[0] * p.reins.length_scale,
        reins[1] * p.reins.length_scale,
        p.stirrups.weight,
        geometry.leathers[0] * p.stirrups.leather_scale,
        geometry.leathers[1] * p.stirrups.leather_scale,
    )


def make_parts(
    geometry: PartsGeometry, ops: PartOps, neutral: Sequence[float], compiled: bool = False
) -> PartsFunction:
    """``parts(knobs, neck_rz, neck_ry, head_rz, *rider) -> tuple`` in :data:`PART_OUTPUTS` order.

    ``knobs``: :func:`parts_knobs` (a tuple, or a float64 array); ``rider``: the values of
    :data:`PART_RIDER_INPUTS` (service units); ``neutral`` the rider skeleton's neutral
    frame (``channels.RIDER`` order, metres: ``rider_rig().neutral``); angles in degrees;
    the outputs are in service units (``reins.slip`` a plain fraction). Floats or NumPy
    arrays, as ``ops`` says.

    The skeletons' geometry is bound into the function (a closure); the preset and the
    unit come in ``knobs``, so ``compiled`` (the same source compiled by numba,
    :func:`riderlive.fastpath.kernel`, with ``SCALAR`` ops and a float64 array of knobs)
    compiles once per skeleton pair, not per parameter change.
    """
    sqrt, sin, cos, maximum = ops.sqrt, ops.sin, ops.cos, ops.maximum
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
    rad = math.pi / 180.0
    tiny = 1e-12

    has_reins = geometry.has_reins
    nx, ny, nz = geometry.neck or (0.0, 0.0, 0.0)
    px, py, _ = geometry.poll
    (gx, gy, lgz), (_, _, rgz) = geometry.rings[0], geometry.rings[1]
    (lhx, lhy, lhz), (rhx, rhy, rhz) = geometry.hands[0], geometry.hands[1]
    (sx0, sy0, lsz), (_, _, rsz) = geometry.shoulders[0], geometry.shoulders[1]
    ox, oy, _ = geometry.lean_pivot
    sx0, sy0 = sx0 - ox, sy0 - oy

    ankles = geometry.ankles or ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    (lax, lay, laz), (rax, ray, raz) = ankles[0], ankles[1]
    (lcx, lcy, lcz), (rcx, rcy, rcz) = geometry.centres[0], geometry.centres[1]
    l_dy, r_dy = lay - lcy, ray - rcy  # the legs' targets keep their rest height (Appendix B moves x and z)
    has_stirrups = geometry.has_stirrups and l_dy < 0.0 and r_dy < 0.0  # from_rigs refuses a bar below its ankle

    def hand(  # noqa: PLR0917 (the live path: positional floats, no packing)
        bx: Any, by: Any, bz: Any, wx: Any, wy: Any, wz: Any, qx0: Any, qy0: Any, qz: Any, rein: Any, k: Any
    ) -> Any:
        """One hand's grip on its rein minus the seat-carried hand ``w`` (service units), and the rein's slip."""
        ex, ey, ez = wx - bx, wy - by, wz - bz
        s = rein / maximum(sqrt(ex * ex + ey * ey + ez * ez), tiny)
        gx_, gy_, gz_ = bx + ex * s, by + ey * s, bz + ez * s
        qx, qy, qz = gx_ - qx0, gy_ - qy0, gz_ - qz  # to the hand from ``q0``: the shoulder less the wrist rules
        q = sqrt(qx * qx + qy * qy + qz * qz)
        over = maximum(q - k[_REACH], 0.0)
        f = over / maximum(q, tiny)
        u = k[_PER_UNIT] * k[_REIN_W]
        return ((gx_ - qx * f - wx) * u, (gy_ - qy * f - wy) * u, (gz_ - qz * f - wz) * u, over / rein)

    def foot(tx: Any, tz: Any, cx: float, dy: float, cz: float, leather: Any, k: Any) -> Any:  # noqa: PLR0917
        """The correction that puts the ankle target ``(tx, rest, tz)`` within ``leather`` of its centre."""
        dx, dz = tx - cx, tz - cz
        d = sqrt(dx * dx + dy * dy + dz * dz)  # > 0: the centre is above the ankle (dy)
        f = maximum(d - leather, 0.0) / d * k[_FOOT_W] * k[_PER_UNIT]
        return (-dx * f, -dy * f, -dz * f)

    def parts(  # noqa: PLR0917
        k: Any,
        neck_rz: Any,
        neck_ry: Any,
        head_rz: Any,
        lift_u: Any,
        shift_u: Any,
        back: Any,
        waist: Any,
        hip: Any,
        lwx: Any,
        lwy: Any,
        rwx: Any,
        rwy: Any,
        lfx: Any,
        lfz: Any,
        rfx: Any,
        rfz: Any,
    ) -> tuple[Any, ...]:
        m = k[_M]
        lift = lift_u * m - n_lift  # metres from here on
        arm = lift * k[_ARM_GAIN] * k[_PER_UNIT]
        zero = 0.0 * arm
        l0 = l1 = l2 = r0 = r1 = r2 = slip = zero
        if has_reins and k[_REIN_W] > 0.0:
            shift = shift_u * m - n_shift
            a, b, c = head_rz * rad, neck_rz * rad, neck_ry * rad
            ch, sh, cn, sn, cy, sy = cos(a), sin(a), cos(b), sin(b), cos(c), sin(c)
            wx = px + gx * ch - gy * sh  # the rings in the neck's frame (they differ only in z)
            wy = py + gx * sh + gy * ch
            ux = wx * cn - wy * sn  # turned up or down by the neck, then sideways
            bx, by, bz = nx + ux * cy, ny + wx * sn + wy * cn, nz - ux * sy
            t = (back + waist + hip - n_lean) * rad  # the trunk's forward lean
            ct, st = cos(t), sin(t)
            qx0 = ox + sx0 * ct + sy0 * st + shift
            qy0 = oy - sx0 * st + sy0 * ct + lift
            l0, l1, l2, l3 = hand(
                bx + lgz * sy,
                by,
                bz + lgz * cy,
                lhx + shift,
                lhy + lift,
                lhz,
                qx0 - (lwx * m - n_lwx),
                qy0 - (lwy * m - n_lwy),
                lsz,
                k[_L_REIN],
                k,
            )
            r0, r1, r2, r3 = hand(
                bx + rgz * sy,
                by,
                bz + rgz * cy,
                rhx + shift,
                rhy + lift,
                rhz,
                qx0 - (rwx * m - n_rwx),
                qy0 - (rwy * m - n_rwy),
                rsz,
                k[_R_REIN],
                k,
            )
            slip = maximum(l3, r3)
        f0 = f1 = f2 = g0 = g1 = g2 = zero
        if has_stirrups and k[_FOOT_W] > 0.0:
            f0, f1, f2 = foot(lax + lfx * m - n_lfx, laz - (lfz * m - n_lfz), lcx, l_dy, lcz, k[_L_LEATHER], k)
            g0, g1, g2 = foot(rax + rfx * m - n_rfx, raz + (rfz * m - n_rfz), rcx, r_dy, rcz, k[_R_LEATHER], k)
        return (l0, l1, l2, r0, r1, r2, arm, arm, f0, f1, f2, g0, g1, g2, slip)

    if not compiled:
        return parts
    from riderlive import fastpath

    if ops is not SCALAR or not fastpath.AVAILABLE:
        raise ValueError("compiled parts need numba and the SCALAR ops")
    fastpath.inline(hand)
    fastpath.inline(foot)
    return fastpath.kernel(parts)


@cache
def compiled_parts(geometry: PartsGeometry, neutral: tuple[float, ...]) -> PartsFunction:
    """:func:`make_parts` compiled for a float64 array of knobs and 16 floats (once per skeleton pair
    in a process; numba's disk cache across processes: ~1 s cold, ~0.3 s from the cache).

    Nothing else is ever compiled: other argument types (ints) are converted to these, so
    no call in a live loop can start a compile."""
    from numba import types

    parts: Any = make_parts(geometry, SCALAR, neutral, compiled=True)
    parts.compile((types.float64[::1], *(types.float64,) * (3 + len(PART_RIDER_INPUTS))))
    parts.disable_compile()
    return cast(PartsFunction, parts)


@dataclass(frozen=True)
class RiderParts:
    """The parts of a preset on one skeleton pair, for rider frames in service units.

    ``metres_per_unit``: the service length unit in metres (``length_scale / 25``).
    ``compiled``: :meth:`evaluate` runs :func:`compiled_parts` (numba; None: when
    installed), else the same source on Python floats.
    """

    params: RuleParams
    metres_per_unit: float = 1.0
    geometry: PartsGeometry | None = None
    """None: :func:`default_geometry`."""
    compiled: bool | None = None

    def __post_init__(self) -> None:
        from riderlive import fastpath
        from riderlive.channels import HORSE_INDEX, RIDER_NAMES
        from riderlive.skeleton.rider import rider_neutral

        geometry = self.geometry or default_geometry()
        neutral_map = rider_neutral()
        neutral = tuple(neutral_map.get(n, 0.0) for n in RIDER_NAMES)
        knobs = parts_knobs(self.params, geometry, self.metres_per_unit)
        compiled = fastpath.AVAILABLE if self.compiled is None else self.compiled
        set_ = object.__setattr__

        def first(*args: Any) -> tuple[Any, ...]:
            """The first frame compiles or loads the compiled function (see :meth:`warm`), then stands aside.

            Where numba cannot (no writable cache directory, a compiler error), the same
            source runs interpreted: the same values, ~7 us a frame instead of ~3; logged."""
            try:
                one = compiled_parts(geometry, neutral)
            except Exception as exc:  # numba's errors have no common base; the parts must go on
                log.warning("rider parts: not compiled (%s: %s); running them interpreted", type(exc).__name__, exc)
                one = make_parts(geometry, SCALAR, neutral)
                args = (knobs, *args[1:])
                set_(self, "_one_knobs", knobs)
            set_(self, "_one", one)
            return one(*args)

        set_(self, "knobs", knobs)
        set_(self, "_one", first if compiled else make_parts(geometry, SCALAR, neutral))
        set_(self, "_one_knobs", np.array(knobs) if compiled else knobs)
        set_(self, "_many", make_parts(geometry, ARRAY, neutral))
        set_(self, "_columns", tuple(HORSE_INDEX[n] for n in PART_INPUTS))
        set_(self, "_pick", itemgetter(*(RIDER_INDEX[n] for n in PART_RIDER_INPUTS)))
        set_(self, "notes", geometry.notes)

    def evaluate(self, horse: Sequence[float], rider: Sequence[float]) -> list[float]:
        """One frame: ``horse`` in ``channels.HORSE`` order, ``rider`` in ``channels.RIDER`` order."""
        i, j, k = self._columns  # type: ignore[attr-defined]
        one: PartsFunction = self._one  # type: ignore[attr-defined]
        return list(one(self._one_knobs, horse[i], horse[j], horse[k], *self._pick(rider)))  # type: ignore[attr-defined]

    def warm(self) -> None:
        """Compile or load the compiled function now (a live loop calls this before its first deadline)."""
        self.evaluate([0.0] * (max(self._columns) + 1), [0.0] * len(RIDER_INDEX))  # type: ignore[attr-defined]

    def evaluate_batch(self, horse: Any, rider: Any) -> Any:
        """N frames: ``horse`` (N, len(HORSE)), ``rider`` (N, len(RIDER)); returns (N, len(PART_OUTPUTS))."""
        horse = np.asarray(horse, dtype=np.float64)
        rider = np.asarray(rider, dtype=np.float64)
        i, j, k = self._columns  # type: ignore[attr-defined]
        picked = self._pick(tuple(rider.T))  # type: ignore[attr-defined]
        values = self._many(self.knobs, horse[:, i], horse[:, j], horse[:, k], *picked)  # type: ignore[attr-defined]
        out = np.empty((len(horse), len(PART_OUTPUTS)))
        for c, v in enumerate(values):
            out[:, c] = v
        return out
