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


def _min_scalar(a: Any, b: Any) -> Any:
    return a if a <= b else b


def _max_scalar(a: Any, b: Any) -> Any:
    return a if a >= b else b


@dataclass(frozen=True, slots=True)
class Ops:
    """The primitives whose scalar and array forms differ."""

    abs: Callable[[Any], Any]
    minimum: Callable[[Any, Any], Any]
    maximum: Callable[[Any, Any], Any]
    where: Callable[[Any, Any, Any], Any]


SCALAR_OPS = Ops(abs=abs, minimum=_min_scalar, maximum=_max_scalar, where=_where_scalar)
ARRAY_OPS = Ops(abs=np.abs, minimum=np.minimum, maximum=np.maximum, where=np.where)

RuleFunction = Callable[..., tuple[Any, ...]]


def make_rules(p: RuleParams, ops: Ops) -> RuleFunction:
    """Return ``rules(*RULE_INPUTS) -> tuple`` in the order of ``channels.RIDER``.

    The preset's numbers are bound to local names first: the live path reads them
    as closure constants, several times faster than attribute look-ups.
    """
    fabs, minimum, maximum, where = ops.abs, ops.minimum, ops.maximum, ops.where
    lbk, sft, sq, hd, wr, ft, kn, hc, er = (
        p.lower_back,
        p.seat_shift,
        p.squash,
        p.head,
        p.wrists,
        p.feet,
        p.knees,
        p.hair_cloth,
        p.errata,
    )
    # Eq. 1-3
    eq1_h1, eq1_w1, eq1_w2, eq1_w3 = (
        lbk.pivot_height_offset,
        lbk.pivot_weight,
        lbk.front_feet_weight,
        lbk.back_feet_weight,
    )
    eq1_h2, eq1_w4, eq1_w5, eq1_w6, eq1_w7 = (
        lbk.pivot_rotation_offset,
        lbk.pivot_rotation_weight,
        lbk.front_height_weight,
        lbk.back_height_weight,
        lbk.height_term_weight,
    )
    front_limit, back_limit = lbk.front_height_limit, lbk.back_height_limit
    eq1_front_clamped_offset = er.front_clamped_lf_tx_offset * 0.5
    side_gain, twist_gain = lbk.side_gain, er.waist_side_from_lower_back * lbk.twist_gain
    # Eq. 4-8
    waist_gain, hip_fwd_gain = p.waist.gain, p.hip.forward_gain
    hip_side_pivot_gain, hip_side_hoof_gain = p.hip.side_pivot_gain, p.hip.side_rear_hoof_gain
    lift_front_gain, lift_gain, lift_limit = p.lift.front_height_gain, p.lift.gain, p.lift.limit
    shift_pivot_gain, shift_gain, shift_limit = sft.pivot_gain, sft.gain, sft.limit
    shift_test_back_gain = er.seat_shift_test_back_gain
    # Eq. 9
    spine_c0, spine_d0, spine_f0 = sq.rest_spine_c - sq.offset, sq.rest_spine_d - sq.offset, sq.rest_spine_f - sq.offset
    neck0, head_a0 = sq.rest_neck - sq.offset, sq.rest_head_a - sq.offset
    spine_div, neck_div = sq.spine_divisor, sq.neck_divisor
    # Eq. 10-13
    head_back_gain, head_lift_gain, head_offset = hd.back_gain, hd.lift_gain, hd.offset
    head_back_min, head_back_max, head_side_gain = hd.back_min, hd.back_max, hd.side_gain
    wrist_back_gain, wrist_pivot_gain, wrist_limit = wr.back_gain, wr.pivot_gain, wr.back_limit
    wrist_clamped = er.wrist_clamped_sign * wr.back_limit
    wrist_height_gain, wrist_height_limit, wrist_pivot_height_gain = (
        wr.height_gain,
        wr.height_limit,
        wr.pivot_height_gain,
    )
    pivot_rest = er.pivot_rest_offset
    # The literal readings of Appendix B's contradictions cost array work only when chosen.
    literal_eq1_offset = eq1_front_clamped_offset != 0.0
    literal_shift_test = shift_test_back_gain != 1.0
    literal_wrist_sign = wrist_clamped != wrist_limit
    literal_pivot_rest = pivot_rest != 0.0
    # Eq. 14-18
    feet_limit, foot_side_gain, foot_side_offset = ft.height_limit, ft.side_gain, ft.side_offset
    foot_twist_gain, foot_twist_offset = ft.twist_gain, ft.twist_offset
    belly_gain, belly_offset, belly_pivot_gain = ft.belly_gain, ft.belly_offset, ft.belly_pivot_gain
    left_clamped_sign, left_clamped_belly_pivot_gain = (
        er.left_foot_clamped_sign,
        er.left_foot_clamped_belly_pivot_gain,
    )
    reach_pivot_gain, reach_offset, reach_mid_gain = ft.forward_pivot_gain, ft.forward_offset, ft.forward_back_mid_gain
    foot_back_gain = ft.forward_back_gain
    foot_pitch_offset, foot_pitch_gain = ft.pitch_offset, ft.pitch_scale * ft.pitch_gain
    knee_rest, knee_belly_gain, knee_from_left = kn.rest_tz, kn.belly_gain, er.right_knee_from_left_foot
    knee_lift_gain, knee_lift_offset = kn.lift_gain, kn.lift_offset
    literal_left_foot = left_clamped_sign != 1.0 or left_clamped_belly_pivot_gain != belly_pivot_gain
    literal_right_knee = knee_from_left != 0.0
    # hair and cloth
    hc_offset, hair_up_gain, cloth_up_gain = hc.height_offset, hc.hair_up_gain, hc.cloth_up_gain
    hair_side_gain = er.waist_side_from_lower_back * hc.hair_side_gain
    cloth_pivot_gain, cloth_hoof_gain = hc.cloth_side_pivot_gain, hc.cloth_side_rear_hoof_gain

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

        # Eq. 1: lower back forward (+) / back; hoof heights used up to 18 (front), 15 (back).
        front_x_eq1 = front_x
        if literal_eq1_offset:  # E7: an offset in the front-clamped-only branch
            only_front_clamped = (front_h >= front_limit) & (back_h < back_limit)
            front_x_eq1 = where(only_front_clamped, front_x - eq1_front_clamped_offset, front_x)
        lower_back = (
            piv_rz * ((piv_ty + eq1_h1) * eq1_w1)
            + back_x * eq1_w3
            - front_x_eq1 * eq1_w2
            + (
                minimum(front_h, front_limit) * ((abs_pitch + eq1_h2) * eq1_w4) * eq1_w5
                - minimum(back_h, back_limit) * eq1_w6
            )
            * eq1_w7
        )
        side = piv_rx * side_gain  # Eq. 2
        twist = side * twist_gain  # Eq. 3
        waist = lower_back * waist_gain  # Eq. 4
        hip_fwd = lower_back * hip_fwd_gain  # Eq. 5
        rear_diff = rb_ty - lb_ty
        hip_side = piv_rx * hip_side_pivot_gain + rear_diff * hip_side_hoof_gain  # Eq. 6

        # Eq. 7: lift out of the seat, limited.
        lift = minimum(
            (fabs(lb_tx - rb_tx) + fabs(lf_tx - rf_tx) - back_x + front_x + front_h * lift_front_gain) * lift_gain,
            lift_limit,
        )

        # Eq. 8: seat shift within +-limit.
        pitch2 = piv_rz * shift_pivot_gain
        shift_value = (pitch2 - lower_back) * shift_gain
        if literal_shift_test:  # E13: the clamp tests the waist, the value uses the lower back
            shift_test = (pitch2 - lower_back * shift_test_back_gain) * shift_gain
            inside = where(shift_test < -shift_limit, -shift_limit, shift_value)
            shift = where(shift_test > shift_limit, shift_limit, inside)
        else:
            shift = minimum(maximum(shift_value, -shift_limit), shift_limit)

        # Eq. 9: squash and stretch.
        spine_lift = lift / spine_div
        neck_lift = lift / neck_div

        # Eq. 10-11: the head counters the lower back (clamped) and the lift.
        head_back = minimum(maximum(lower_back, head_back_min), head_back_max)
        head_fwd = -head_back * head_back_gain - lift * head_lift_gain + head_offset
        head_side = piv_rx * head_side_gain

        # Eq. 12-13: wrists, the lower back clamped to +-17.
        if literal_wrist_sign:  # E5: the clamped branches flip the sign
            back_high, back_low = lower_back >= wrist_limit, lower_back <= -wrist_limit
            wrist_back = where(back_high, wrist_clamped, where(back_low, -wrist_clamped, lower_back))
        else:
            wrist_back = minimum(maximum(lower_back, -wrist_limit), wrist_limit)
        wrist_pitch = abs_pitch
        if literal_pivot_rest:  # E6: 0.572 in the lower-back <= -17 branch
            wrist_pitch = where(lower_back <= -wrist_limit, fabs(piv_rz - pivot_rest), abs_pitch)
        wrist_fwd = wrist_back * wrist_back_gain - front_x * (wrist_pitch * wrist_pivot_gain)
        wrist_up = minimum(all_h, wrist_height_limit) * wrist_height_gain - piv_ty * wrist_pivot_height_gain

        # Eq. 16-17 and the knee lift: the hoof height sum is used up to 15.
        h15 = minimum(all_h, feet_limit)
        rt_side = h15 * foot_side_gain + foot_side_offset
        rt_twist = -h15 * foot_twist_gain + foot_twist_offset
        lf_twist = h15 * foot_twist_gain + foot_twist_offset
        belly = h15 * belly_gain + belly_offset
        rt_belly = belly - piv_rx * belly_pivot_gain
        lf_side, lf_belly = rt_side, rt_belly
        if literal_left_foot:  # E4: the left foot's clamped branch flips sign and uses 0.02
            feet_clamped = all_h > feet_limit
            lf_side = where(feet_clamped, left_clamped_sign * rt_side, rt_side)
            lf_clamped = left_clamped_sign * belly - piv_rx * left_clamped_belly_pivot_gain
            lf_belly = where(feet_clamped, lf_clamped, rt_belly)
        knee_lift = h15 * knee_lift_gain + knee_lift_offset

        # Eq. 14-15: feet forward/back; the front-hoof term only ever moves the feet back.
        reach = front_x * -(abs_pitch * reach_pivot_gain + reach_offset + mid_rz * reach_mid_gain)
        foot_pitch = abs_pitch
        if literal_pivot_rest:  # E6: 0.572 in the forward branch
            foot_pitch = where(reach <= 0.0, abs_pitch, fabs(piv_rz - pivot_rest))
        foot_fwd = minimum(reach, 0.0) - foot_pitch * lower_back * foot_back_gain
        foot_rz = (foot_fwd + foot_pitch_offset) * foot_pitch_gain

        # Eq. 18: knees against the feet.
        lf_knee = knee_rest - lf_belly * knee_belly_gain
        rt_knee = knee_rest - rt_belly * knee_belly_gain
        if literal_right_knee:  # E14: the right knee reads the left foot
            rt_knee = knee_rest - (rt_belly + (lf_belly - rt_belly) * knee_from_left) * knee_belly_gain

        heights = all_h + hc_offset
        hair_up = heights * hair_up_gain
        hair_side = heights * side * hair_side_gain
        cloth_up = heights * cloth_up_gain
        cloth_side = piv_rx * cloth_pivot_gain + rear_diff * cloth_hoof_gain

        return (
            lower_back,
            side,
            twist,
            waist,
            hip_fwd,
            hip_side,
            lift,
            shift,
            spine_c0 + spine_lift,
            spine_d0 + spine_lift,
            spine_f0 + spine_lift,
            neck0 + neck_lift,
            head_a0 + neck_lift,
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
