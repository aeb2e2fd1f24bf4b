"""The rider rules of Kuhnel (2003), Appendix B, written once for two backends.

:func:`make_rules` binds a preset's numbers into a function of the thirteen horse
values the rules read. The same source runs on Python floats (one live frame) and
on NumPy arrays (a whole take): only the four primitives of :class:`Ops` differ.

Inputs are in the thesis rig's units (lengths) and degrees. The order of evaluation
is the dependency order of the thesis: the lower back first (it feeds the waist,
hips, seat shift, head, wrists and feet), then the lift (it feeds squash and head).
Where Appendix B contradicts itself, the reading is set by ``params.errata`` and
documented in ``docs/rules.md``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from riderlive.rules.params import RuleParams

RULE_INPUTS: tuple[str, ...] = (
    "lfHoof.tx",
    "lfHoof.ty",
    "rfHoof.tx",
    "rfHoof.ty",
    "lbHoof.tx",
    "lbHoof.ty",
    "rbHoof.tx",
    "rbHoof.ty",
    "rearPivot.tx",
    "rearPivot.ty",
    "rearPivot.rx",
    "rearPivot.rz",
    "backMid.rz",
)
"""The horse channels the rules read, in the argument order of the rule function."""


def _where_scalar(cond: Any, a: Any, b: Any) -> Any:
    return a if cond else b


@dataclass(frozen=True, slots=True)
class Ops:
    """The primitives whose scalar and array forms differ."""

    abs: Callable[[Any], Any]
    minimum: Callable[[Any, Any], Any]
    maximum: Callable[[Any, Any], Any]
    where: Callable[[Any, Any, Any], Any]


SCALAR_OPS = Ops(abs=abs, minimum=min, maximum=max, where=_where_scalar)
ARRAY_OPS = Ops(abs=np.abs, minimum=np.minimum, maximum=np.maximum, where=np.where)

RuleFunction = Callable[..., tuple[Any, ...]]


def make_rules(p: RuleParams, ops: Ops) -> RuleFunction:
    """Return ``rules(*RULE_INPUTS) -> tuple`` in the order of ``channels.RIDER``."""
    fabs, minimum, maximum, where = ops.abs, ops.minimum, ops.maximum, ops.where
    lbk, wst, hip, lft, sft = p.lower_back, p.waist, p.hip, p.lift, p.seat_shift
    sq, hd, wr, ft, kn, hc, er = p.squash, p.head, p.wrists, p.feet, p.knees, p.hair_cloth, p.errata

    def rules(  # noqa: PLR0917 - one argument per horse value, in RULE_INPUTS order
        lf_tx: Any,
        lf_ty: Any,
        rf_tx: Any,
        rf_ty: Any,
        lb_tx: Any,
        lb_ty: Any,
        rb_tx: Any,
        rb_ty: Any,
        piv_tx: Any,
        piv_ty: Any,
        piv_rx: Any,
        piv_rz: Any,
        mid_rz: Any,
    ) -> tuple[Any, ...]:
        front_h = lf_ty + rf_ty  # height sum of the front hooves
        back_h = lb_ty + rb_ty  # height sum of the back hooves
        all_h = front_h + back_h
        front_x = piv_tx - (lf_tx + rf_tx) * 0.5  # front hooves behind the pivot: > 0
        back_x = piv_tx - (lb_tx + rb_tx) * 0.5
        abs_pitch = fabs(piv_rz)

        # Eq. 1: lower back forward/back; the hoof heights are used up to 18 / 15.
        only_front_clamped = (front_h >= lbk.front_height_limit) & (back_h < lbk.back_height_limit)
        front_x_eq1 = where(only_front_clamped, front_x - er.front_clamped_lf_tx_offset * 0.5, front_x)
        lower_back = (
            piv_rz * ((piv_ty + lbk.pivot_height_offset) * lbk.pivot_weight)
            + back_x * lbk.back_feet_weight
            - front_x_eq1 * lbk.front_feet_weight
            + (
                minimum(front_h, lbk.front_height_limit)
                * ((abs_pitch + lbk.pivot_rotation_offset) * lbk.pivot_rotation_weight)
                * lbk.front_height_weight
                - minimum(back_h, lbk.back_height_limit) * lbk.back_height_weight
            )
            * lbk.height_term_weight
        )
        side = piv_rx * lbk.side_gain  # Eq. 2
        twist = side * er.waist_side_from_lower_back * lbk.twist_gain  # Eq. 3
        waist = lower_back * wst.gain  # Eq. 4
        hip_fwd = lower_back * hip.forward_gain  # Eq. 5
        rear_diff = rb_ty - lb_ty
        hip_side = piv_rx * hip.side_pivot_gain + rear_diff * hip.side_rear_hoof_gain  # Eq. 6

        # Eq. 7: lift, limited.
        lift = minimum(
            (fabs(lb_tx - rb_tx) + fabs(lf_tx - rf_tx) - back_x + front_x + front_h * lft.front_height_gain) * lft.gain,
            lft.limit,
        )

        # Eq. 8: seat shift within +-limit.
        pitch2 = piv_rz * sft.pivot_gain
        shift_test = (pitch2 - lower_back * er.seat_shift_test_back_gain) * sft.gain
        shift = where(
            shift_test > sft.limit,
            sft.limit,
            where(shift_test < -sft.limit, -sft.limit, (pitch2 - lower_back) * sft.gain),
        )

        # Eq. 9: squash and stretch.
        spine_lift = lift / sq.spine_divisor
        neck_lift = lift / sq.neck_divisor

        # Eq. 10 (head) and Eq. 12 (wrists forward/back) use the lower back clamped.
        head_back = minimum(maximum(lower_back, hd.back_min), hd.back_max)
        head_fwd = -head_back * hd.back_gain - lift * hd.lift_gain + hd.offset
        head_side = piv_rx * hd.side_gain  # Eq. 11
        wrist_back = where(
            lower_back >= wr.back_limit,
            er.wrist_clamped_sign * wr.back_limit,
            where(lower_back <= -wr.back_limit, -er.wrist_clamped_sign * wr.back_limit, lower_back),
        )
        wrist_pitch = where(lower_back <= -wr.back_limit, fabs(piv_rz - er.pivot_rest_offset), abs_pitch)
        wrist_fwd = wrist_back * wr.back_gain - front_x * (wrist_pitch * wr.pivot_gain)
        # Eq. 13
        wrist_up = minimum(all_h, wr.height_limit) * wr.height_gain - piv_ty * wr.pivot_height_gain

        # Eq. 16-17 and the knee lift: the hoof height sum is used up to 15.
        feet_clamped = all_h > ft.height_limit
        h15 = minimum(all_h, ft.height_limit)
        rt_side = h15 * ft.side_gain + ft.side_offset
        lf_side = where(feet_clamped, er.left_foot_clamped_sign * rt_side, rt_side)
        rt_twist = -h15 * ft.twist_gain + ft.twist_offset
        lf_twist = h15 * ft.twist_gain + ft.twist_offset
        belly = h15 * ft.belly_gain + ft.belly_offset
        rt_belly = belly - piv_rx * ft.belly_pivot_gain
        lf_belly = where(
            feet_clamped,
            er.left_foot_clamped_sign * belly - piv_rx * er.left_foot_clamped_belly_pivot_gain,
            rt_belly,
        )
        knee_lift = h15 * kn.lift_gain + kn.lift_offset

        # Eq. 14: feet forward/back; the front-hoof term only ever moves the feet back.
        reach = front_x * -(abs_pitch * ft.forward_pivot_gain + ft.forward_offset + mid_rz * ft.forward_back_mid_gain)
        reach_back = reach <= 0.0
        foot_pitch = where(reach_back, abs_pitch, fabs(piv_rz - er.pivot_rest_offset))
        foot_fwd = minimum(reach, 0.0) - foot_pitch * lower_back * ft.forward_back_gain
        foot_rz = (foot_fwd + ft.pitch_offset) * ft.pitch_scale * ft.pitch_gain  # Eq. 15

        # Eq. 18: knees against the feet.
        rt_knee = kn.rest_tz - (rt_belly + (lf_belly - rt_belly) * er.right_knee_from_left_foot) * kn.belly_gain
        lf_knee = kn.rest_tz - lf_belly * kn.belly_gain

        heights = all_h + hc.height_offset
        hair_up = heights * hc.hair_up_gain
        hair_side = heights * (side * er.waist_side_from_lower_back) * hc.hair_side_gain
        cloth_up = heights * hc.cloth_up_gain
        cloth_side = piv_rx * hc.cloth_side_pivot_gain + rear_diff * hc.cloth_side_rear_hoof_gain

        return (
            lower_back,
            side,
            twist,
            waist,
            hip_fwd,
            hip_side,
            lift,
            shift,
            sq.rest_spine_c - sq.offset + spine_lift,
            sq.rest_spine_d - sq.offset + spine_lift,
            sq.rest_spine_f - sq.offset + spine_lift,
            sq.rest_neck - sq.offset + neck_lift,
            sq.rest_head_a - sq.offset + neck_lift,
            head_fwd,
            head_side,
            wrist_fwd,
            wrist_fwd,
            wrist_up,
            wrist_up,
            foot_fwd,
            foot_fwd,
            foot_rz,
            foot_rz,
            lf_side,
            rt_side,
            lf_twist,
            rt_twist,
            lf_belly,
            rt_belly,
            lf_knee,
            rt_knee,
            knee_lift,
            knee_lift,
            hair_up,
            hair_side,
            cloth_up,
            cloth_side,
        )

    return rules
