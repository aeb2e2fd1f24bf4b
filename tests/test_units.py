"""Length units: the one conversion between the service's length unit and metres."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.channels import HORSE, RIDER, SADDLE, Kind
from riderlive.horse import DEFAULT_SCALE
from riderlive.units import (
    HORSE_LENGTHS,
    RIDER_LENGTHS,
    RIG_UNITS_PER_METRE,
    SADDLE_LENGTHS,
    horse_lengths,
    metres_per_unit,
    units_per_metre,
)


def test_one_rig_unit_per_metre_everywhere() -> None:
    assert RIG_UNITS_PER_METRE == DEFAULT_SCALE == 25.0
    assert metres_per_unit(25.0) == 1.0 and metres_per_unit(1.0) == 0.04 and metres_per_unit(2500.0) == 100.0
    assert units_per_metre(25.0) == 1.0 and units_per_metre(1.0) == 25.0 and units_per_metre(0.25) == 100.0


@settings(deadline=None)  # a busy host stalls a case for 100s of ms: not what this checks
@given(st.floats(min_value=1e-3, max_value=1e5))
def test_units_per_metre_is_the_inverse(length_scale: float) -> None:
    assert units_per_metre(length_scale) * metres_per_unit(length_scale) == pytest.approx(1.0, rel=1e-15)


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf])
def test_a_length_scale_that_is_no_unit_is_refused(bad: float) -> None:
    with pytest.raises(ValueError, match="length_scale"):
        metres_per_unit(bad)


def test_the_length_columns_are_the_translations_and_only_those() -> None:
    for table, columns in ((HORSE, HORSE_LENGTHS), (RIDER, RIDER_LENGTHS), (SADDLE, SADDLE_LENGTHS)):
        assert {i for i, c in enumerate(table) if c.kind is Kind.TRANSLATION} == set(columns)
        assert all(table[i].attr in ("tx", "ty", "tz") for i in columns)
    assert SADDLE_LENGTHS == (0, 1, 2)


@given(
    st.lists(st.floats(-1e3, 1e3), min_size=len(HORSE), max_size=len(HORSE)),
    st.floats(1e-3, 1e3),
)
def test_lengths_scale_and_come_back_angles_never_move(frame: list[float], k: float) -> None:
    lengths = horse_lengths(k)
    metres = lengths.to_metres(frame)
    for i, (a, b) in enumerate(zip(frame, metres, strict=True)):
        assert b == (a * k if i in HORSE_LENGTHS else a)
    assert lengths.from_metres(metres) == pytest.approx(frame, rel=1e-12, abs=1e-12)
    rows = np.array([frame, frame])
    lengths.rows_to_metres(rows)
    assert rows.tolist() == [metres, metres]
