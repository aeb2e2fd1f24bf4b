"""The resampler: interpolation, hold bound, no extrapolation, clock mapping."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.realtime.resample import Resampler


def test_interpolates_linearly_between_frames() -> None:
    r = Resampler(delay=0.0, hold=1.0)
    r.push(10.0, 100.0, [0.0, 2.0])
    r.push(10.1, 100.1, [1.0, 4.0])
    # offset = 90: engine 100.05 shows source 10.05, halfway.
    t, frame = r.sample(100.05)  # type: ignore[misc]
    assert abs(t - 10.05) < 1e-9
    np.testing.assert_allclose(frame, [0.5, 3.0])


def test_holds_the_newest_frame_for_at_most_hold_then_is_stale() -> None:
    r = Resampler(delay=0.0, hold=0.25)
    r.push(0.0, 5.0, [1.0])
    assert r.sample(5.2) == (0.0, [1.0])
    assert r.sample(5.25) == (0.0, [1.0])
    assert r.sample(5.26) is None


def test_delay_reads_the_past_and_the_least_delayed_frame_sets_the_clock() -> None:
    r = Resampler(delay=0.05, hold=1.0)
    r.push(0.00, 1.030, [0.0])  # arrived 30 ms late
    r.push(0.01, 1.012, [1.0])  # arrived 2 ms late: the clock offset is 1.002
    r.push(0.02, 1.040, [2.0])
    assert r.offset == 1.002
    t, frame = r.sample(1.067)  # type: ignore[misc]
    assert abs(t - 0.015) < 1e-12 and abs(frame[0] - 1.5) < 1e-9


def test_old_and_repeated_frames_are_dropped() -> None:
    r = Resampler()
    assert r.push(1.0, 1.0, [1.0])
    assert not r.push(1.0, 1.1, [2.0])
    assert not r.push(0.5, 1.2, [3.0])
    assert list(r.times) == [1.0]


def test_capacity_drops_the_oldest_and_keeps_the_offset_right() -> None:
    r = Resampler(capacity=4)
    for i in range(10):
        r.push(float(i), float(i) + (0.001 if i == 2 else 0.01), [float(i)])
    assert list(r.times) == [6.0, 7.0, 8.0, 9.0]
    assert abs(r.offset - 0.01) < 1e-12, "the minimum of the frames still buffered"


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.floats(0.001, 0.1), min_size=2, max_size=30),
    st.lists(st.floats(-100, 100), min_size=30, max_size=30),
    st.floats(-1.0, 5.0),
    st.floats(0.0, 0.3),
)
def test_never_leaves_the_range_of_the_frames_around_it(gaps, values, query, hold) -> None:
    r = Resampler(delay=0.0, hold=hold)
    t = 0.0
    times = []
    for gap, value in zip(gaps, values, strict=False):
        t += gap
        times.append(t)
        r.push(t, t, [value])  # offset 0: engine time == source time
    n = len(times)
    result = r.sample(query)
    if query > times[-1] + hold:
        assert result is None, "stale: never extrapolated"
        return
    assert result is not None
    shown_t, (value,) = result
    assert shown_t <= times[-1], "never past the newest frame"
    lo, hi = min(values[:n]), max(values[:n])
    assert lo - 1e-9 <= value <= hi + 1e-9
    if times[0] <= query <= times[-1]:
        i = int(np.searchsorted(times, query, side="right"))
        i = min(max(i, 1), n - 1)
        a, b = values[i - 1], values[i]
        assert min(a, b) - 1e-9 <= value <= max(a, b) + 1e-9, "between its two neighbours"
