"""The input ring's record (``realtime/layout.py``): packed and read back by name."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from riderlive.realtime import layout as L

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@given(
    producer=st.integers(-(2**52), 2**52),
    t=finite,
    received=finite,
    values=st.lists(st.floats(allow_infinity=False, width=64), min_size=0, max_size=L.N_HORSE),
    kind=st.sampled_from(L.InputKind),
    rebased=st.booleans(),
)
def test_a_record_reads_back_as_packed(
    producer: int, t: float, received: float, values: list[float], kind: L.InputKind, rebased: bool
) -> None:
    row = L.InputRecord(producer, t, received, values, kind, rebased).row()
    assert row.shape == (L.INPUT_WIDTH,) and row.dtype == np.float64
    back = L.InputRecord.of(row)
    assert (back.producer, back.t, back.received, back.kind, back.rebased) == (producer, t, received, kind, rebased)
    assert len(back.values) == L.N_HORSE  # unused trailing values are NaN
    assert all(math.isnan(v) for v in back.values[len(values) :])
    assert all(a == b or (math.isnan(a) and math.isnan(b)) for a, b in zip(back.values, values, strict=False))


def test_a_row_without_the_flag_written_is_not_rebased() -> None:
    """A row whose flag column holds anything but 1 (a NaN-filled row) reads as not rebased."""
    row = np.full(L.INPUT_WIDTH, np.nan)
    row[[L.IN_PRODUCER, L.IN_T, L.IN_RECEIVED, L.IN_KIND]] = 3, 1.5, 2.5, L.InputKind.SADDLE
    assert L.InputRecord.of(row)[:3] == (3, 1.5, 2.5)
    assert L.InputRecord.of(row).kind is L.InputKind.SADDLE and not L.InputRecord.of(row).rebased
