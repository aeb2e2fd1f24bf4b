"""The scalar (live), NumPy and compiled (bake) paths give the same numbers, on every branch."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.channels import HORSE, HORSE_INDEX, RIDER, RIDER_INDEX
from riderlive.rules.animator import AnimatorLayer
from riderlive.rules.engine import RiderModel
from riderlive.rules.params import RuleParams, load_preset, shipped_presets


def random_frames(n: int, seed: int) -> np.ndarray:
    """Frames spread wide enough to reach every clamp branch of Appendix B."""
    rng = np.random.default_rng(seed)
    horse = rng.normal(scale=6.0, size=(n, len(HORSE)))
    for hoof in ("lfHoof", "rfHoof", "lbHoof", "rbHoof"):
        horse[:, HORSE_INDEX[f"{hoof}.ty"]] = rng.uniform(0.0, 14.0, n)
    horse[:, HORSE_INDEX["rearPivot.rz"]] = rng.normal(scale=18.0, size=n)
    horse[:, HORSE_INDEX["rearPivot.ty"]] = rng.uniform(-2.0, 20.0, n)
    return horse


def branch_coverage(horse: np.ndarray, rider: np.ndarray) -> dict[str, bool]:
    h = {name: horse[:, HORSE_INDEX[name]] for name in HORSE_INDEX}
    front = h["lfHoof.ty"] + h["rfHoof.ty"]
    back = h["lbHoof.ty"] + h["rbHoof.ty"]
    lower_back = rider[:, RIDER_INDEX["lower_back.rz"]]
    shift = rider[:, RIDER_INDEX["cog.tx"]]
    reach = rider[:, RIDER_INDEX["lf_foot.tx"]]
    return {
        "eq1 none clamped": bool(np.any((front < 18) & (back < 15))),
        "eq1 front clamped": bool(np.any((front >= 18) & (back < 15))),
        "eq1 back clamped": bool(np.any((front < 18) & (back >= 15))),
        "eq1 both clamped": bool(np.any((front >= 18) & (back >= 15))),
        "lower back >= 17": bool(np.any(lower_back >= 17)),
        "lower back in (-17, 17)": bool(np.any(np.abs(lower_back) < 17)),
        "lower back in (-20, -17]": bool(np.any((lower_back <= -17) & (lower_back > -20))),
        "lower back <= -20": bool(np.any(lower_back <= -20)),
        "shift > 1": bool(np.any(shift == 1.0)),
        "shift < -1": bool(np.any(shift == -1.0)),
        "shift inside": bool(np.any(np.abs(shift) < 1.0)),
        "feet sum <= 15": bool(np.any(front + back <= 15)),
        "feet sum > 15": bool(np.any(front + back > 15)),
        "wrist sum >= 20": bool(np.any(front + back >= 20)),
        "foot reach both ways": bool(np.any(reach > 0) and np.any(reach < 0)),
    }


@pytest.mark.parametrize("compiled", [False, True])
@pytest.mark.parametrize("preset", ["kuhnel2003", "kuhnel2003_literal"])
def test_scalar_and_batch_agree_on_every_branch(preset: str, compiled: bool) -> None:
    model = RiderModel(params=load_preset(preset))
    horse = random_frames(5000, seed=7)
    batch = model.evaluate_batch(horse, compiled=compiled)
    scalar = np.array([model.evaluate(row) for row in horse.tolist()])
    np.testing.assert_allclose(scalar, batch, rtol=0.0, atol=1e-12)
    coverage = branch_coverage(horse, batch)
    assert all(coverage.values()), [name for name, hit in coverage.items() if not hit]


@pytest.mark.parametrize("preset", ["kuhnel2003", "kuhnel2003_literal"])
def test_compiled_batch_with_scale_animator_and_block_edges(preset: str) -> None:
    """The compiled kernel (one compile per preset; scale and animator are run-time inputs) on frames that
    span several blocks, equal to the scalar path to 1e-12; absent columns read as zero."""
    from riderlive.fastpath import BLOCK
    from riderlive.rules.kuhnel2003 import RULE_INPUTS

    animator = AnimatorLayer(offsets={"head.rz": 2.5, "cog.ty": -0.1}, gains={"lower_back.rz": 1.3})
    model = RiderModel(params=load_preset(preset), scale=2.5, animator=animator)
    horse = random_frames(2 * BLOCK + 3, seed=5)
    batch = model.evaluate_batch(horse, compiled=True)
    scalar = np.array([model.evaluate(row) for row in horse.tolist()])
    np.testing.assert_allclose(scalar, batch, rtol=0.0, atol=1e-12)
    assert batch.shape == (2 * BLOCK + 3, len(RIDER)) and batch[:, 0].flags.c_contiguous  # one row per channel
    assert model.evaluate_batch(horse[:0], compiled=True).shape == (0, len(RIDER))
    read = (*RULE_INPUTS, "ground.rz")  # the rules' inputs and the ground's pitch (rules/terrain.py)
    without_mid = {n: horse[:, HORSE_INDEX[n]] for n in read if n != "backMid.rz"}
    zeroed = horse.copy()
    zeroed[:, HORSE_INDEX["backMid.rz"]] = 0.0
    np.testing.assert_array_equal(
        model.evaluate_columns(without_mid, len(horse), compiled=True), model.evaluate_batch(zeroed, compiled=False)
    )


@pytest.mark.parametrize("preset", shipped_presets())
def test_every_shipped_preset_agrees_with_scale_and_animator(preset: str) -> None:
    animator = AnimatorLayer(offsets={"head.rz": 2.5, "cog.ty": -0.1}, gains={"lower_back.rz": 1.3})
    model = RiderModel(params=load_preset(preset), scale=2.5, animator=animator)
    horse = random_frames(2000, seed=11)
    scalar = np.array([model.evaluate(row) for row in horse.tolist()])
    np.testing.assert_allclose(scalar, model.evaluate_batch(horse), rtol=0.0, atol=1e-9)


def test_batch_handles_empty_and_chunk_edges() -> None:
    from riderlive.rules.engine import BATCH_CHUNK

    model = RiderModel()
    assert model.evaluate_batch(np.zeros((0, len(HORSE)))).shape == (0, len(RIDER))
    horse = random_frames(BATCH_CHUNK * 2 + 3, seed=3)
    batch = model.evaluate_batch(horse)
    for i in (0, BATCH_CHUNK - 1, BATCH_CHUNK, 2 * BATCH_CHUNK + 2):
        np.testing.assert_allclose(model.evaluate(horse[i].tolist()), batch[i], rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="expected an"):
        model.evaluate_batch(np.zeros((4, 3)))


finite = st.floats(min_value=-1e3, max_value=1e3, allow_nan=False, allow_infinity=False)


@settings(max_examples=300, deadline=None)
@given(st.lists(finite, min_size=len(HORSE), max_size=len(HORSE)))
def test_clamps_hold_for_any_frame(frame: list[float]) -> None:
    """Appendix B's clamps (the [jump] layer, which moves the trunk and head over a fence, is off:
    its own bounds are tested in test_jump.py)."""
    model = RiderModel(RuleParams().with_values({"jump.weight": 0.0}))
    out = model.evaluate(frame)
    assert out[RIDER_INDEX["cog.ty"]] <= 15.0
    assert -1.0 <= out[RIDER_INDEX["cog.tx"]] <= 1.0
    # head.rz = -clamp(lb, -20, 17)*0.9 - lift*18 + 5, so without the lift it stays in [-10.3, 23]
    lift = out[RIDER_INDEX["cog.ty"]]
    head_without_lift = out[RIDER_INDEX["head.rz"]] + lift * 18.0
    assert -10.3 - 1e-9 <= head_without_lift <= 23.0 + 1e-9
    # wrist forward: the lower back enters at most as +-17 * 0.0001
    h = dict(zip([c.name for c in HORSE], frame, strict=True))
    front_x = h["rearPivot.tx"] - (h["lfHoof.tx"] + h["rfHoof.tx"]) / 2
    pitch_term = front_x * abs(h["rearPivot.rz"] - h["ground.rz"]) * 0.008  # the pitch relative to the ground
    assert abs(out[RIDER_INDEX["lf_wrist.tz"]] + pitch_term) <= 17 * 0.0001 + 1e-9
    np.testing.assert_allclose(out, model.evaluate_batch(np.array([frame]))[0], rtol=0, atol=1e-9)


@settings(max_examples=100, deadline=None)
@given(
    st.lists(st.floats(-50, 50), min_size=len(HORSE), max_size=len(HORSE)),
    st.floats(min_value=0.01, max_value=100.0),
)
def test_length_scale_maps_units_in_and_out(frame: list[float], scale: float) -> None:
    """A horse in other units, with its scale, gives the rig-unit result rescaled."""
    from riderlive.channels import Kind

    in_rig_units = [v * scale if c.kind is Kind.TRANSLATION else v for v, c in zip(frame, HORSE, strict=True)]
    reference = RiderModel().evaluate(in_rig_units)
    scaled = RiderModel(scale=scale).evaluate(frame)
    expected = [v / scale if c.kind is Kind.TRANSLATION else v for v, c in zip(reference, RIDER, strict=True)]
    np.testing.assert_allclose(scaled, expected, rtol=1e-9, atol=1e-9)


def test_scale_must_be_positive() -> None:
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="scale"):
            RiderModel(scale=bad)
