"""One test per reading of docs/rules.md's errata table (E1-E15).

Where Appendix B contradicts itself, the chosen reading keeps the rider continuous
across each clamp boundary; ``kuhnel2003_literal`` keeps the contradiction and jumps.
"""

from __future__ import annotations

import pytest

from riderlive.rules.engine import RiderModel
from riderlive.rules.params import RuleParams, load_preset
from tests.rules.conftest import horse_frame, rider

EPS = 1e-9


def jump(model: RiderModel, channel: str, below: list[float], above: list[float]) -> float:
    return abs(rider(model.evaluate(above), channel) - rider(model.evaluate(below), channel))


def test_e1_lfhoofctrl_is_the_left_front_hoof(thesis: RiderModel) -> None:
    """``lfhoofCtrl`` and ``lfHoofCtrl`` are one node: both front hooves count alike."""
    a = thesis.evaluate(horse_frame(lfHoof_ty=7.0, rfHoof_ty=2.0, rearPivot_rz=4.0))
    b = thesis.evaluate(horse_frame(lfHoof_ty=2.0, rfHoof_ty=7.0, rearPivot_rz=4.0))
    for channel in ("lower_back.rz", "cog.ty", "lf_wrist.ty", "lf_foot.ry", "lf_foot.tz"):
        assert rider(a, channel) == pytest.approx(rider(b, channel), abs=1e-12)


def test_e2_nurbscircle6_reads_the_rear_pivot(thesis: RiderModel) -> None:
    """In Eq. 1's third branch the pivot still cancels: moving the pivot changes nothing."""
    base = dict(lbHoof_ty=9.0, rbHoof_ty=9.0, lfHoof_tx=2.0, rfHoof_tx=1.0, lbHoof_tx=-2.0, rbHoof_tx=-1.0)
    at_zero = rider(thesis.evaluate(horse_frame(**base)), "lower_back.rz")
    moved = rider(thesis.evaluate(horse_frame(rearPivot_tx=5.0, **base)), "lower_back.rz")
    assert moved == pytest.approx(at_zero, abs=1e-12)


def test_e3_belly_translation_is_tz_and_forward_is_tx(thesis: RiderModel) -> None:
    """The in/out expression drives foot.tz (the knee reads it); Eq. 14 alone drives foot.tx."""
    grounded = thesis.evaluate(horse_frame(rearPivot_rx=2.0))
    lifted = thesis.evaluate(horse_frame(rearPivot_rx=2.0, lbHoof_ty=2.0, rbHoof_ty=2.0))
    assert rider(lifted, "lf_foot.tz") == pytest.approx(rider(grounded, "lf_foot.tz") - 4 * 0.05)
    assert rider(lifted, "lf_knee.tz") == pytest.approx(-1.1 * rider(lifted, "lf_foot.tz"))
    assert rider(grounded, "lf_foot.tx") == 0.0  # no hoof reach, no pitch: Eq. 14 is zero


def test_e4_left_foot_clamp_branch_mirrors_the_unclamped_branch(thesis: RiderModel, literal: RiderModel) -> None:
    below = horse_frame(lfHoof_ty=7.5, rfHoof_ty=7.5 - EPS, rearPivot_rx=3.0)
    above = horse_frame(lfHoof_ty=7.5, rfHoof_ty=7.5 + EPS, rearPivot_rx=3.0)
    for channel in ("lf_foot.ry", "lf_foot.tz", "lf_knee.tz"):
        assert jump(thesis, channel, below, above) < 1e-6
        assert jump(literal, channel, below, above) > 1.0


def test_e5_wrist_clamp_keeps_the_sign_of_the_lower_back(thesis: RiderModel, literal: RiderModel) -> None:
    # lower back = pitch * (0 + 2) * 0.07 = 17 at pitch 17 / 0.14
    edge = 17.0 / 0.14
    for sign in (1.0, -1.0):
        below = horse_frame(rearPivot_rz=sign * (edge - 1e-6))
        above = horse_frame(rearPivot_rz=sign * (edge + 1e-6))
        assert jump(thesis, "lf_wrist.tz", below, above) < 1e-8
        assert jump(literal, "lf_wrist.tz", below, above) == pytest.approx(2 * 17 * 0.0001, rel=1e-3)


def test_e6_no_0572_pivot_offset(thesis: RiderModel, literal: RiderModel) -> None:
    # Eq. 14: the forward branch (reach > 0) against the backward one, at reach = 0.
    below = horse_frame(lfHoof_tx=1e-9, rfHoof_tx=1e-9, rearPivot_rz=10.0, lbHoof_tx=-40.0, rbHoof_tx=-40.0)
    above = horse_frame(lfHoof_tx=-1e-9, rfHoof_tx=-1e-9, rearPivot_rz=10.0, lbHoof_tx=-40.0, rbHoof_tx=-40.0)
    assert jump(thesis, "lf_foot.tx", below, above) < 1e-8
    assert jump(literal, "lf_foot.tx", below, above) > 1e-3
    assert load_preset("kuhnel2003_literal").errata.pivot_rest_offset == 0.572


def test_e7_no_25_offset_when_only_the_front_is_clamped(thesis: RiderModel, literal: RiderModel) -> None:
    below = horse_frame(lfHoof_ty=9.0, rfHoof_ty=9.0 - EPS)
    above = horse_frame(lfHoof_ty=9.0, rfHoof_ty=9.0 + EPS)
    assert jump(thesis, "lower_back.rz", below, above) < 1e-8
    assert jump(literal, "lower_back.rz", below, above) == pytest.approx(0.3125, rel=1e-6)


def test_e8_head_side_follows_the_roll_at_08(thesis: RiderModel) -> None:
    """Appendix B's 0.8 (same direction as the horse) over section 8's -1."""
    assert rider(thesis.evaluate(horse_frame(rearPivot_rx=10.0)), "head.ry") == pytest.approx(8.0)


def test_e9_feet_forward_offset_is_008(thesis: RiderModel) -> None:
    """Appendix B's 0.08 over section 8's 0.8: reach = 2 * -(0 + 0.08 + 0) = -0.16."""
    out = thesis.evaluate(horse_frame(lfHoof_tx=-2.0, rfHoof_tx=-2.0))
    assert rider(out, "lf_foot.tx") == pytest.approx(-0.16)


def test_e10_low_backctrl_is_lower_back(thesis: RiderModel) -> None:
    """The hips read ``low_backCTRL``, the head branches test it: it is the lower back."""
    out = thesis.evaluate(horse_frame(rearPivot_rz=100.0))  # lower back 14 (not clamped)
    assert rider(out, "hip.rz") == pytest.approx(0.8 * rider(out, "lower_back.rz"))
    assert rider(out, "head.rz") == pytest.approx(-0.9 * 14.0 - 0.0 + 5.0)


def test_e11_knee_initial_position_is_a_parameter() -> None:
    params = RuleParams().with_values({"knees.rest_tz": 0.75})
    out = RiderModel(params=params).evaluate(horse_frame(lbHoof_ty=1.0))
    assert rider(out, "lf_knee.tz") == pytest.approx(0.75 - 1.1 * rider(out, "lf_foot.tz"))


def test_e12_waist_side_is_the_lower_back_side(thesis: RiderModel) -> None:
    out = thesis.evaluate(horse_frame(rearPivot_rx=6.0, lfHoof_ty=1.0, rbHoof_ty=3.0))
    assert rider(out, "lower_back.rx") == pytest.approx(0.5 * rider(out, "lower_back.ry"))
    assert rider(out, "hair.side") == pytest.approx((4.0 - 2.0) * -6.0 * -0.02)


def test_e13_seat_shift_tests_and_computes_the_same_quantity(thesis: RiderModel, literal: RiderModel) -> None:
    # shift = (2*pitch - lower back)*0.1 with lower back = -32*0.25*... crossing 1 at back hooves 40
    below = horse_frame(lbHoof_tx=40.0 - 1e-6, rbHoof_tx=40.0 - 1e-6)  # lower back -10 -> shift 1
    above = horse_frame(lbHoof_tx=40.0 + 1e-6, rbHoof_tx=40.0 + 1e-6)
    assert jump(thesis, "cog.tx", below, above) < 1e-6
    # the literal test uses the waist (1.7x): it clamps to 1 from lower back -5.88 on
    early = horse_frame(lbHoof_tx=30.0, rbHoof_tx=30.0)  # lower back -7.5: value 0.75, waist test 1.275
    assert rider(thesis.evaluate(early), "cog.tx") == pytest.approx(0.75)
    assert rider(literal.evaluate(early), "cog.tx") == 1.0


def test_e14_each_knee_reads_its_own_foot(thesis: RiderModel, literal: RiderModel) -> None:
    clamped = horse_frame(lfHoof_ty=10.0, rfHoof_ty=10.0, rearPivot_rx=4.0)
    out = thesis.evaluate(clamped)
    assert rider(out, "rt_knee.tz") == pytest.approx(-1.1 * rider(out, "rt_foot.tz"))
    lit = literal.evaluate(clamped)
    assert rider(lit, "rt_knee.tz") == pytest.approx(-1.1 * rider(lit, "lf_foot.tz"))


def test_e15_foot_ry_is_side_to_side_with_17(thesis: RiderModel) -> None:
    """Appendix comments call ry 'twist'; the axis convention and Eq. 16 make it side to side."""
    out = thesis.evaluate(horse_frame(lbHoof_ty=2.0))
    assert rider(out, "lf_foot.ry") == pytest.approx(2.0 * -1.7 - 1.0)
    assert rider(out, "rt_foot.rx") == pytest.approx(2.0 * -0.1 + 1.0)
