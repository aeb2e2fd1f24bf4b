"""The rider does what the thesis says a rider does (sections 5, 6, 8 and 9)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from riderlive.channels import HORSE, HORSE_INDEX, RIDER_INDEX
from riderlive.rules.engine import RiderModel
from tests.rules.conftest import horse_frame, rider


def test_front_feet_raised_with_rear_pivot_rotated_leans_forward(thesis: RiderModel) -> None:
    """Section 8.1: with pitch in the rear pivot, lifting the front feet leans the rider forward."""
    grounded = rider(thesis.evaluate(horse_frame(rearPivot_rz=15.0, rearPivot_ty=6.0)), "lower_back.rz")
    lifting = [
        rider(
            thesis.evaluate(horse_frame(rearPivot_rz=15.0, rearPivot_ty=6.0, lfHoof_ty=h, rfHoof_ty=h)), "lower_back.rz"
        )
        for h in (1.0, 3.0, 6.0, 8.0)
    ]
    assert lifting[-1] > grounded > 0.0
    assert all(b > a for a, b in zip(lifting, lifting[1:], strict=False))
    # ... and the more pitch, the more each unit of front-hoof height counts, in both directions.
    up = [
        rider(thesis.evaluate(horse_frame(rearPivot_rz=p, lfHoof_ty=4.0, rfHoof_ty=4.0)), "lower_back.rz")
        - rider(thesis.evaluate(horse_frame(rearPivot_rz=p)), "lower_back.rz")
        for p in (-20.0, 0.0, 20.0)
    ]
    assert up[0] == pytest.approx(up[2]) and up[0] > up[1] > 0.0


def test_hooves_toward_the_centre_lean_back_and_out_lean_forward(thesis: RiderModel) -> None:
    """Section 8.1, figures 19-20: both sets in -> back; both sets out -> forward."""
    inward = horse_frame(lfHoof_tx=-3.0, rfHoof_tx=-3.0, lbHoof_tx=3.0, rbHoof_tx=3.0)
    outward = horse_frame(lfHoof_tx=3.0, rfHoof_tx=3.0, lbHoof_tx=-3.0, rbHoof_tx=-3.0)
    assert rider(thesis.evaluate(inward), "lower_back.rz") < 0.0
    assert rider(thesis.evaluate(outward), "lower_back.rz") > 0.0
    # The sets counteract: front forward but back further forward -> slightly back.
    both_forward = horse_frame(lfHoof_tx=1.0, rfHoof_tx=1.0, lbHoof_tx=2.0, rbHoof_tx=2.0)
    assert -1.0 < rider(thesis.evaluate(both_forward), "lower_back.rz") < 0.0


def test_seat_slides_back_as_rider_leans_forward_without_pitch(thesis: RiderModel) -> None:
    """Section 8.4 and 9.3: seat slides back when leaning forward, forward when leaning back."""
    forward = thesis.evaluate(horse_frame(lfHoof_tx=3.0, rfHoof_tx=3.0, lbHoof_tx=-3.0, rbHoof_tx=-3.0))
    back = thesis.evaluate(horse_frame(lfHoof_tx=-3.0, rfHoof_tx=-3.0, lbHoof_tx=3.0, rbHoof_tx=3.0))
    assert rider(forward, "cog.tx") < 0.0 < rider(back, "cog.tx")


def trot_frames(n: int = 240, reach: float = 4.0) -> tuple[np.ndarray, np.ndarray]:
    """A synthetic trot: diagonal pairs swing together, each pair's hooves in antiphase."""
    phase = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    horse = np.zeros((n, len(HORSE)))
    swing = reach * np.sin(phase)
    for hoof, sign, base in (("lf", 1, 6.0), ("rb", 1, -6.0), ("rf", -1, 6.0), ("lb", -1, -6.0)):
        horse[:, HORSE_INDEX[f"{hoof}Hoof.tx"]] = base + sign * swing
        horse[:, HORSE_INDEX[f"{hoof}Hoof.ty"]] = np.maximum(0.0, sign * 1.5 * np.cos(phase))
    return phase, horse


def test_trot_lift_peaks_when_each_pair_is_furthest_apart(thesis: RiderModel) -> None:
    """Section 9.2: the rider bounces up as the legs spread and sinks as they pass."""
    phase, horse = trot_frames()
    lift = thesis.evaluate_batch(horse)[:, RIDER_INDEX["cog.ty"]]
    spread = np.abs(horse[:, HORSE_INDEX["lfHoof.tx"]] - horse[:, HORSE_INDEX["rfHoof.tx"]])
    half = len(phase) // 2
    for window in (slice(0, half), slice(half, None)):  # one bounce per half stride: twice per stride
        lift_peak = phase[window][np.argmax(lift[window])]
        spread_peak = phase[window][np.argmax(spread[window])]
        # the front hooves' height (a swing hoof is highest mid-stride) shifts the peak a little
        assert abs(lift_peak - spread_peak) < math.radians(15.0)
        assert lift[window].max() - lift[window].min() > 0.1
    assert np.corrcoef(lift, spread)[0, 1] > 0.9


def test_hips_side_to_side_follow_the_rear_hooves_height_difference(thesis: RiderModel) -> None:
    """Section 8.2, figure 25: one hind leg higher tilts the rider's hips."""
    diffs = np.linspace(-3.0, 3.0, 13)
    hips = [rider(thesis.evaluate(horse_frame(rbHoof_ty=max(d, 0.0), lbHoof_ty=max(-d, 0.0))), "hip.ry") for d in diffs]
    np.testing.assert_allclose(np.diff(hips), 2.0 * np.diff(diffs), atol=1e-12)
    rolled = rider(thesis.evaluate(horse_frame(rearPivot_rx=6.0)), "hip.ry")
    assert rolled == pytest.approx(3.0)  # half of the horse's hip roll, same direction


def test_rider_leans_against_the_horse_roll_and_head_follows_it(thesis: RiderModel) -> None:
    """Section 8.1 (Eq. 2, figure 23) and 8.6 (figure 36)."""
    out = thesis.evaluate(horse_frame(rearPivot_rx=5.0))
    assert rider(out, "lower_back.ry") == -5.0
    assert rider(out, "head.ry") > 0.0


def test_head_counters_the_lean_and_the_lift(thesis: RiderModel) -> None:
    """Section 8.6: the head rotates against the lower back and nods with the lift."""
    lean = thesis.evaluate(horse_frame(lfHoof_tx=3.0, rfHoof_tx=3.0, lbHoof_tx=-3.0, rbHoof_tx=-3.0))
    assert rider(lean, "lower_back.rz") > 0.0
    assert rider(lean, "head.rz") < 5.0
    rest = thesis.evaluate(horse_frame())
    assert rider(rest, "head.rz") == 5.0  # five degrees down at rest
