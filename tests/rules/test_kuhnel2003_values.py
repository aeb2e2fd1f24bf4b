"""Every equation against values computed by hand from Appendix B.

Each expected number below was worked out on paper from the Appendix B expressions
(the arithmetic is in the comments), not by running the code under test.
"""

from __future__ import annotations

import pytest

from riderlive.rules.engine import RiderModel
from tests.rules.conftest import horse_frame, rider

# Frame A: no clamp engaged.
#   lf.tx=2 rf.tx=0 lb.tx=-1 rb.tx=-3; lf.ty=1 rb.ty=2; pivot tx=0 ty=10 rx=4 rz=10
#   front sum F=1, back sum B=2, all S=3
#   front_x = pivot.tx - mean(front tx) = 0 - 1 = -1;  back_x = 0 - (-2) = 2
FRAME_A = horse_frame(
    lfHoof_tx=2.0,
    rfHoof_tx=0.0,
    lbHoof_tx=-1.0,
    rbHoof_tx=-3.0,
    lfHoof_ty=1.0,
    rbHoof_ty=2.0,
    rearPivot_ty=10.0,
    rearPivot_rx=4.0,
    rearPivot_rz=10.0,
)

EXPECTED_A = {
    # Eq. 1: 10*(10+2)*0.07 + 2*0.25 + (-1)*-0.25 + (1*((10+5)*0.1)*0.9 - 2*0.4)*0.4
    #      = 8.4 + 0.5 + 0.25 + 0.22
    "lower_back.rz": 9.37,
    "lower_back.ry": -4.0,  # Eq. 2: 4 * -1
    "lower_back.rx": -2.0,  # Eq. 3: -4 * 0.5
    "waist.rz": 15.929,  # Eq. 4: 9.37 * 1.7
    "hip.rz": 7.496,  # Eq. 5: 9.37 * 0.8
    "hip.ry": 6.0,  # Eq. 6: 4*0.5 + (2-0)*2
    "cog.ty": 0.03,  # Eq. 7: (|-1+3| + |2-0| + 2*-1 + -1 + 1*2) * 0.01
    "cog.tx": 1.0,  # Eq. 8: (10*2 - 9.37)*0.1 = 1.063 > 1 -> 1
    "spine_c.ty": 0.387,  # Eq. 9: 0.482 - 0.1 + 0.03/6
    "spine_d.ty": 0.469,  # 0.564 - 0.1 + 0.005
    "spine_f.ty": 0.854,  # 0.949 - 0.1 + 0.005
    "neck.ty": 1.292 + 0.03 / 7,  # 1.392 - 0.1 + 0.03/7
    "head_a.ty": 0.902 + 0.03 / 7,  # 1.002 - 0.1 + 0.03/7
    "head.rz": -3.973,  # Eq. 10: -9.37*0.9 - 0.03*18 + 5
    "head.ry": 3.2,  # Eq. 11: 4 * 0.8
    "lf_wrist.tz": 0.080937,  # Eq. 12: 9.37*0.0001 - (-1)*(10*0.008)
    "rt_wrist.tz": 0.080937,
    "lf_wrist.ty": 0.085,  # Eq. 13: 3*0.03 - 10*0.0005
    "rt_wrist.ty": 0.085,
    # Eq. 14: reach = -1 * -(10*0.005 + 0.08 + 0) = 0.13 > 0 -> 0 - |10|*9.37*0.005
    "lf_foot.tx": -0.4685,
    "rt_foot.tx": -0.4685,
    "lf_foot.rz": -30.378,  # Eq. 15: (-0.4685 + 3) * -6 * 2
    "rt_foot.rz": -30.378,
    "lf_foot.ry": -6.1,  # Eq. 16: 3*-1.7 - 1
    "rt_foot.ry": -6.1,
    "lf_foot.rx": 1.3,  # 3*0.1 + 1
    "rt_foot.rx": 0.7,  # 3*-0.1 + 1
    "lf_foot.tz": 1.65,  # Eq. 17: 3*-0.05 + 2 - 4*0.05
    "rt_foot.tz": 1.65,
    "lf_knee.tz": -1.815,  # Eq. 18: 0 - 1.65*1.1
    "rt_knee.tz": -1.815,
    "lf_knee.ty": -0.91,  # 3*0.03 - 1
    "rt_knee.ty": -0.91,
    "hair.up": 0.7,  # (3-2)*0.7
    "hair.side": 0.08,  # (3-2) * (-4) * -0.02
    "cloth.up": 0.7,
    "cloth.side": -6.0,  # 4*-0.5 + (2-0)*-2
}


@pytest.mark.parametrize("channel", sorted(EXPECTED_A))
def test_frame_without_clamps(thesis: RiderModel, channel: str) -> None:
    assert rider(thesis.evaluate(FRAME_A), channel) == pytest.approx(EXPECTED_A[channel], abs=1e-12)


def test_every_rider_channel_has_a_hand_value() -> None:
    from riderlive.channels import RIDER_NAMES

    assert set(EXPECTED_A) == set(RIDER_NAMES)


# Frame B: both front hooves at 10 (F=20 >= 18), back on the ground: Eq. 1 uses 18.
FRAME_B = horse_frame(lfHoof_ty=10.0, rfHoof_ty=10.0)


def test_front_height_clamp_18(thesis: RiderModel, literal: RiderModel) -> None:
    # Eq. 1 second branch: (18*((0+5)*0.1)*0.9 - 0*0.4)*0.4 = 3.24
    assert rider(thesis.evaluate(FRAME_B), "lower_back.rz") == pytest.approx(3.24, abs=1e-12)
    # Literal: + ((0 - (0+2.5+0)/2) * -0.25) = +0.3125
    assert rider(literal.evaluate(FRAME_B), "lower_back.rz") == pytest.approx(3.5525, abs=1e-12)
    # Raised further, nothing changes: the 18 is a limit.
    higher = horse_frame(lfHoof_ty=30.0, rfHoof_ty=10.0)
    assert rider(thesis.evaluate(higher), "lower_back.rz") == pytest.approx(3.24, abs=1e-12)


def test_back_height_clamp_15(thesis: RiderModel) -> None:
    # Eq. 1 third branch: (0 - 15*0.4)*0.4 = -2.4 (unclamped would be 18*0.4*0.4 = -2.88)
    frame = horse_frame(lbHoof_ty=9.0, rbHoof_ty=9.0)
    assert rider(thesis.evaluate(frame), "lower_back.rz") == pytest.approx(-2.4, abs=1e-12)
    # Both clamped (fourth branch): (18*0.5*0.9 - 15*0.4)*0.4 = 0.84
    both = horse_frame(lfHoof_ty=10.0, rfHoof_ty=10.0, lbHoof_ty=9.0, rbHoof_ty=9.0)
    assert rider(thesis.evaluate(both), "lower_back.rz") == pytest.approx(0.84, abs=1e-12)


def test_feet_knees_wrists_height_sums_15_and_20(thesis: RiderModel, literal: RiderModel) -> None:
    out = thesis.evaluate(FRAME_B)  # S = 20
    assert rider(out, "rt_foot.ry") == pytest.approx(-26.5, abs=1e-12)  # 15*-1.7 - 1
    assert rider(out, "lf_foot.ry") == pytest.approx(-26.5, abs=1e-12)
    assert rider(out, "rt_foot.rx") == pytest.approx(-0.5, abs=1e-12)  # 15*-0.1 + 1
    assert rider(out, "lf_foot.rx") == pytest.approx(2.5, abs=1e-12)  # 15*0.1 + 1
    assert rider(out, "rt_foot.tz") == pytest.approx(1.25, abs=1e-12)  # 15*-0.05 + 2
    assert rider(out, "lf_knee.ty") == pytest.approx(-0.55, abs=1e-12)  # 15*0.03 - 1
    assert rider(out, "lf_wrist.ty") == pytest.approx(0.6, abs=1e-12)  # 20*0.03 - 0
    assert rider(out, "cog.ty") == pytest.approx(0.4, abs=1e-12)  # Eq. 7: 20*2*0.01
    lit = literal.evaluate(FRAME_B)
    assert rider(lit, "lf_foot.ry") == pytest.approx(26.5, abs=1e-12)  # 15*1.7 + 1
    assert rider(lit, "lf_foot.tz") == pytest.approx(-1.25, abs=1e-12)  # 15*0.05 - 2
    assert rider(lit, "rt_knee.tz") == pytest.approx(1.375, abs=1e-12)  # 0 - (-1.25)*1.1
    over = thesis.evaluate(horse_frame(lfHoof_ty=20.0, rbHoof_ty=20.0))  # S = 40
    assert rider(over, "lf_wrist.ty") == pytest.approx(0.6, abs=1e-12)


def test_lift_limited_to_15(thesis: RiderModel) -> None:
    # (0 + 0 - 0 + 0 + 1000*2) * 0.01 = 20 -> 15
    out = thesis.evaluate(horse_frame(lfHoof_ty=1000.0))
    assert rider(out, "cog.ty") == 15.0
    assert rider(out, "spine_c.ty") == pytest.approx(0.382 + 15 / 6, abs=1e-12)


def test_seat_shift_within_one(thesis: RiderModel, literal: RiderModel) -> None:
    # Unclamped: lower back = 1*(0+2)*0.07 = 0.14; shift = (1*2 - 0.14)*0.1 = 0.186
    out = thesis.evaluate(horse_frame(rearPivot_rz=1.0))
    assert rider(out, "cog.tx") == pytest.approx(0.186, abs=1e-12)
    # Back hooves 32 ahead of the pivot: lower back = -32*0.25 = -8; shift = 0.8.
    # The literal test uses the waist (-13.6): (0 + 13.6)*0.1 = 1.36 > 1 -> 1.
    lean_back = horse_frame(lbHoof_tx=32.0, rbHoof_tx=32.0)
    assert rider(thesis.evaluate(lean_back), "lower_back.rz") == pytest.approx(-8.0, abs=1e-12)
    assert rider(thesis.evaluate(lean_back), "cog.tx") == pytest.approx(0.8, abs=1e-12)
    assert rider(literal.evaluate(lean_back), "cog.tx") == 1.0
    assert rider(thesis.evaluate(horse_frame(rearPivot_rz=-40.0)), "cog.tx") == -1.0


def test_lower_back_17_on_head_and_wrists(thesis: RiderModel, literal: RiderModel) -> None:
    # Pivot pitch 25 at height 10: lower back = 25*12*0.07 = 21 >= 17
    frame = horse_frame(rearPivot_ty=10.0, rearPivot_rz=25.0)
    out = thesis.evaluate(frame)
    assert rider(out, "lower_back.rz") == pytest.approx(21.0, abs=1e-12)
    assert rider(out, "head.rz") == pytest.approx(-10.3, abs=1e-12)  # -17*0.9 - 0 + 5
    assert rider(out, "lf_wrist.tz") == pytest.approx(0.0017, abs=1e-12)  # 17*0.0001 - 0
    assert rider(literal.evaluate(frame), "lf_wrist.tz") == pytest.approx(-0.0017, abs=1e-12)


def test_lower_back_minus_17_and_minus_20(thesis: RiderModel, literal: RiderModel) -> None:
    # Pitch -25, height 10, front hooves 2 behind the pivot (front_x = 2):
    # lower back = -25*12*0.07 - 2*0.25 = -21.5 <= -20; lift = 2*0.01 = 0.02
    frame = horse_frame(lfHoof_tx=-2.0, rfHoof_tx=-2.0, rearPivot_ty=10.0, rearPivot_rz=-25.0)
    out = thesis.evaluate(frame)
    assert rider(out, "lower_back.rz") == pytest.approx(-21.5, abs=1e-12)
    assert rider(out, "head.rz") == pytest.approx(22.64, abs=1e-12)  # 20*0.9 - 0.02*18 + 5
    # -17*0.0001 - 2*(25*0.008)
    assert rider(out, "lf_wrist.tz") == pytest.approx(-0.4017, abs=1e-12)
    # literal: 17*0.0001 - 2*(|-25 - 0.572|*0.008)
    assert rider(literal.evaluate(frame), "lf_wrist.tz") == pytest.approx(-0.407452, abs=1e-12)
    # Between -20 and -17 the head uses the lower back itself: pitch -22 -> -18.48
    mid = thesis.evaluate(horse_frame(rearPivot_ty=10.0, rearPivot_rz=-22.0))
    assert rider(mid, "head.rz") == pytest.approx(18.48 * 0.9 + 5, abs=1e-12)


def test_feet_forward_branch_where_reach_is_backward(thesis: RiderModel) -> None:
    # front_x = 2, pitch 10, mid-back 5: reach = 2 * -(10*0.005 + 0.08 + 5*0.02) = -0.46 <= 0
    # lower back = 10*2*0.07 - 2*0.25 = 0.9; foot = -0.46 - 10*0.9*0.005 = -0.505
    frame = horse_frame(lfHoof_tx=-2.0, rfHoof_tx=-2.0, rearPivot_rz=10.0, backMid_rz=5.0)
    out = thesis.evaluate(frame)
    assert rider(out, "lower_back.rz") == pytest.approx(0.9, abs=1e-12)
    assert rider(out, "lf_foot.tx") == pytest.approx(-0.505, abs=1e-12)
    assert rider(out, "rt_foot.rz") == pytest.approx((3 - 0.505) * -12, abs=1e-12)


def test_literal_foot_forward_branch_uses_0572(literal: RiderModel) -> None:
    # Frame A: reach > 0, literal: 0 - |10 - 0.572| * 9.37 * 0.005 = -0.4416993
    assert rider(literal.evaluate(FRAME_A), "lf_foot.tx") == pytest.approx(-9.428 * 9.37 * 0.005, abs=1e-12)


def test_literal_twist_and_braid_side_are_zero(literal: RiderModel) -> None:
    # waistCTRL.rotateY is never assigned in Appendix B: the literal twist and braid side are 0.
    out = literal.evaluate(FRAME_A)
    assert rider(out, "lower_back.rx") == 0.0
    assert rider(out, "hair.side") == 0.0
