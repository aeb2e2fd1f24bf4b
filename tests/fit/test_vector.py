"""The parameter vector: preset -> vector -> preset round trip, bounds, ties."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.fit.vector import FIT_GROUPS, HELD_GROUPS, ParamKind, clamp, from_vector, parameters, to_vector
from riderlive.rules.params import RuleParams, load_preset

START = load_preset("kuhnel2003")
PARAMS = parameters(START)
NAMES = [p.name for p in PARAMS]


def test_every_number_of_the_fitted_groups_is_a_parameter_and_none_of_the_held() -> None:
    flat = START.flat()
    assert set(NAMES) == {k for k in flat if k.split(".")[0] in FIT_GROUPS}
    assert not any(n.split(".")[0] in HELD_GROUPS for n in NAMES)
    kinds = {p.name: p.kind for p in PARAMS}
    assert kinds["lift.limit"] is ParamKind.CLAMP and kinds["head.back_min"] is ParamKind.CLAMP
    assert kinds["squash.rest_neck"] is ParamKind.OFFSET and kinds["waist.gain"] is ParamKind.WEIGHT
    bounds = {p.name: (p.lower, p.upper) for p in PARAMS}
    assert bounds["seat_shift.limit"] == (0.0, math.inf)
    assert bounds["terrain.upright"] == (0.0, 1.0)
    assert bounds["squash.spine_divisor"][0] > 0.0
    assert bounds["waist.gain"] == (-math.inf, math.inf)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-50.0, 50.0, allow_nan=False), min_size=len(NAMES), max_size=len(NAMES)))
def test_a_clamped_vector_round_trips_through_a_valid_preset(values: list[float]) -> None:
    x = clamp(np.array(values), PARAMS)
    assert all(p.lower <= v <= p.upper for p, v in zip(PARAMS, x, strict=True))
    x[[NAMES.index("squash.spine_divisor"), NAMES.index("squash.neck_divisor")]] += 1.0  # away from the margin
    preset = from_vector(START, NAMES, x)
    assert isinstance(preset, RuleParams)
    np.testing.assert_array_equal(to_vector(preset, NAMES), x)
    held = {k: v for k, v in START.flat().items() if k.split(".")[0] not in FIT_GROUPS}
    for key, value in held.items():
        if key != "errata.left_foot_clamped_belly_pivot_gain":
            assert preset.flat()[key] == value


def test_the_left_foots_clamped_gain_follows_the_belly_gain_only_where_the_preset_tied_them() -> None:
    x = to_vector(START, NAMES)
    x[NAMES.index("feet.belly_pivot_gain")] = 0.07
    assert from_vector(START, NAMES, x).errata.left_foot_clamped_belly_pivot_gain == 0.07
    literal = load_preset("kuhnel2003_literal")
    assert from_vector(literal, NAMES, x).errata.left_foot_clamped_belly_pivot_gain == 0.02
