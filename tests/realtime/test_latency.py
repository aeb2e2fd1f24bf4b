"""The log-spaced latency histogram: buckets, exact quantiles to one bucket, windows, exposition."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.realtime import latency
from riderlive.realtime.latency import BOUNDS, N_BOUNDS, PER_OCTAVE, LatencyHistogram, bucket_index

HALF_BUCKET = 2.0 ** (1.0 / (2 * PER_OCTAVE))
"""A quantile read from a bucket is within this factor of the true one."""


def test_bounds_are_log_spaced_powers_of_two() -> None:
    assert BOUNDS[0] == 2.0**-17
    assert BOUNDS[-1] == 2.0
    assert BOUNDS[PER_OCTAVE] == 2.0**-16
    ratios = np.diff(np.log2(BOUNDS))
    assert np.allclose(ratios, 1.0 / PER_OCTAVE, rtol=0, atol=1e-12)


@given(st.floats(min_value=0.0, max_value=10.0, allow_nan=False))
def test_bucket_holds_the_value(x: float) -> None:
    k = bucket_index(x)
    upper = BOUNDS[k] if k < N_BOUNDS else math.inf
    lower = BOUNDS[k - 1] if k > 0 else -math.inf
    assert lower < x <= upper or (k == 0 and x <= BOUNDS[0])


def test_bucket_edges_exactly() -> None:
    for k in (0, 1, 17, 100, N_BOUNDS - 1):
        assert bucket_index(BOUNDS[k]) == k  # a bound belongs to the bucket it closes (Prometheus "le")
        assert bucket_index(math.nextafter(BOUNDS[k], math.inf)) == k + 1
    assert bucket_index(0.0) == 0
    assert bucket_index(-1.0) == 0
    assert bucket_index(math.nan) == 0
    assert bucket_index(math.inf) == N_BOUNDS


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.floats(min_value=1e-5, max_value=1.5), min_size=1, max_size=400),
    st.sampled_from([0.5, 0.9, 0.99, 0.999, 1.0]),
)
def test_quantile_within_half_a_bucket_of_the_samples(samples: list[float], q: float) -> None:
    histogram = LatencyHistogram()
    for x in samples:
        histogram.observe(x)
    snap = histogram.snapshot()
    ordered = sorted(samples)
    exact = ordered[max(1, math.ceil(q * len(ordered))) - 1]  # the sample at rank ceil(q n)
    got = snap.quantile(q)
    assert exact / HALF_BUCKET * (1 - 1e-12) <= got <= exact * HALF_BUCKET * (1 + 1e-12)
    assert snap.maximum == max(samples)
    assert snap.count == len(samples)
    assert math.isclose(snap.total, sum(samples), rel_tol=1e-9)


def test_hand_counted_quantiles() -> None:
    histogram = LatencyHistogram()
    for _ in range(99):
        histogram.observe(0.001)
    histogram.observe(0.1)
    snap = histogram.snapshot()
    k = bucket_index(0.001)
    middle = math.sqrt(BOUNDS[k - 1] * BOUNDS[k])
    assert snap.quantile(0.5) == pytest.approx(middle)
    assert snap.quantile(0.99) == pytest.approx(middle)  # rank 99 of 100 is still 1 ms
    assert 0.1 / HALF_BUCKET <= snap.quantile(0.995) <= 0.1  # rank 100: its bucket's middle, at most the max
    assert snap.summary()["max"] == 0.1
    assert snap.summary()["mean"] == pytest.approx((99 * 0.001 + 0.1) / 100)
    assert math.isnan(LatencyHistogram().snapshot().quantile(0.5))
    assert LatencyHistogram().snapshot().summary()["p99"] is None


def test_window_since_an_earlier_snapshot() -> None:
    histogram = LatencyHistogram()
    for _ in range(10):
        histogram.observe(0.05)
    before = histogram.snapshot()
    for _ in range(5):
        histogram.observe(0.002)
    window = histogram.snapshot().since(before)
    assert window.count == 5
    assert window.total == pytest.approx(0.01)
    assert window.maximum == BOUNDS[bucket_index(0.002)]  # the old 50 ms max is not in this window
    assert window.quantile(1.0) <= BOUNDS[bucket_index(0.002)]
    histogram.observe(0.2)
    assert histogram.snapshot().since(before).maximum == 0.2  # a new max is exact


def test_shared_views_and_bad_storage() -> None:
    block = np.zeros(2 * latency.SLOTS)
    views = latency.views(block, ("a", "b"))
    views["b"].observe(0.003)
    assert block[: latency.SLOTS].sum() == 0.0
    assert views["b"].count == 1
    assert len(latency.slot_names(("a", "b"))) == len(block)
    with pytest.raises(ValueError):
        LatencyHistogram(np.zeros(3))


def test_prometheus_exposition_is_cumulative_and_consistent() -> None:
    histogram = LatencyHistogram()
    for x in (1e-6, 0.0004, 0.009, 0.009, 3.0):
        histogram.observe(x)
    lines = histogram.snapshot().samples("x_seconds")
    buckets = [line for line in lines if line.startswith("x_seconds_bucket")]
    counts = [int(line.rsplit(" ", 1)[1]) for line in buckets]
    assert counts == sorted(counts)
    assert buckets[-1] == 'x_seconds_bucket{le="+Inf"} 5'
    assert "x_seconds_count 5" in lines
    le = {float(line.split('"')[1]): int(line.rsplit(" ", 1)[1]) for line in buckets[:-1]}
    assert le[2.0**-11] == 2  # 1 us and 0.4 ms are <= 0.49 ms
    assert le[2.0**-6] == 4  # the 9 ms pair too; 3 s only in +Inf
    assert len(buckets) == len(range(0, N_BOUNDS, latency.PROMETHEUS_EVERY)) + 1
