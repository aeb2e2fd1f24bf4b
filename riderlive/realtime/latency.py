"""Latency histograms with fixed log-spaced buckets: exact to one bucket, cheap to fill.

Bucket ``k`` (``k = 0 .. N_BOUNDS - 1``) holds values in ``(bound(k - 1), bound(k)]``
with ``bound(k) = 2 ** (LOWEST_EXPONENT + k / PER_OCTAVE)`` seconds: 16 buckets per
octave from 7.6 us to 2 s (a bucket is 4.4 % wide), one below (everything down to 0)
and one above (+Inf). A quantile is read as the geometric middle of the bucket that
holds it, so it is within 2.2 % of the true sample quantile (tested against NumPy's on
the same samples); the maximum and the sum are kept exactly.

The counts live in a flat float64 array of :data:`SLOTS` values (``count``, ``sum``,
``max``, then the buckets), which may be a view of shared memory: the tick process
fills tick lateness, ingest-to-wire and ingest-to-tick there, and the web process reads them for
``/metrics`` and ``/api/latency``. One writer per histogram; a reader may see a count
a few observations behind the buckets, never a torn float.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from riderlive.prometheus import sample

PER_OCTAVE = 16
LOWEST_EXPONENT = -17
"""The lowest bound is 2**-17 s = 7.6 us."""
N_BOUNDS = 18 * PER_OCTAVE + 1
"""Finite bounds, 2**-17 .. 2**1 s (2 s)."""
BOUNDS: tuple[float, ...] = tuple(2.0 ** (LOWEST_EXPONENT + k / PER_OCTAVE) for k in range(N_BOUNDS))
COUNT, SUM, MAX, FIRST_BUCKET = 0, 1, 2, 3
SLOTS = FIRST_BUCKET + N_BOUNDS + 1
"""Floats per histogram: count, sum, max, the finite buckets, +Inf."""
PROMETHEUS_EVERY = 4
"""``/metrics`` shows every 4th bound (4 per octave, 19 % wide): cumulative counts at a
subset of the bounds are still a valid Prometheus histogram, with 73 series, not 290."""
QUANTILES = (0.5, 0.9, 0.99, 0.999)


def bucket_index(seconds: float) -> int:
    """The bucket holding ``seconds``: 0 for anything up to the lowest bound, ``N_BOUNDS`` above 2 s."""
    if not seconds > BOUNDS[0]:  # also NaN: counted, in the lowest bucket, never lost
        return 0
    if seconds > BOUNDS[-1]:
        return N_BOUNDS
    k = math.ceil((math.log2(seconds) - LOWEST_EXPONENT) * PER_OCTAVE - 1e-9)
    if BOUNDS[k] < seconds:  # rounding at a bound: the bucket whose upper bound holds it
        k += 1
    elif k > 0 and BOUNDS[k - 1] >= seconds:
        k -= 1
    return k


class LatencyHistogram:
    """One histogram over ``values`` (a float64 array of :data:`SLOTS`; a fresh one if None)."""

    def __init__(self, values: np.ndarray | None = None) -> None:
        if values is None:
            values = np.zeros(SLOTS)
        if values.shape != (SLOTS,) or values.dtype != np.float64:
            raise ValueError(f"a latency histogram needs {SLOTS} float64 slots")
        self.values = values

    def observe(self, seconds: float) -> None:
        v = self.values
        v[FIRST_BUCKET + bucket_index(seconds)] += 1.0
        if math.isfinite(seconds):
            v[SUM] += seconds
            v[MAX] = max(v[MAX], seconds)
        v[COUNT] += 1.0

    @property
    def count(self) -> int:
        return int(self.values[COUNT])

    def counts(self) -> np.ndarray:
        """A copy of the bucket counts (``N_BOUNDS + 1``, the last is +Inf)."""
        return self.values[FIRST_BUCKET:].copy()

    def snapshot(self) -> LatencySnapshot:
        v = self.values.copy()
        return LatencySnapshot(v[FIRST_BUCKET:], float(v[SUM]), float(v[MAX]))


class LatencySnapshot:
    """Bucket counts frozen at one moment; subtract two to get a window's."""

    def __init__(self, counts: np.ndarray, total: float, maximum: float) -> None:
        self.buckets = counts
        self.total = total
        self.maximum = maximum
        """Exact for the whole history; for a window (``since``) the upper bound of its highest bucket."""

    @property
    def count(self) -> int:
        return int(self.buckets.sum())

    def since(self, earlier: LatencySnapshot) -> LatencySnapshot:
        """What was observed after ``earlier`` (its maximum: the exact one if it grew, else a bucket's bound)."""
        buckets = self.buckets - earlier.buckets
        if self.maximum > earlier.maximum:
            maximum = self.maximum
        else:
            top = np.flatnonzero(buckets)
            maximum = 0.0 if not len(top) else min(self.maximum, _upper(int(top[-1])))
        return LatencySnapshot(buckets, self.total - earlier.total, maximum)

    def quantile(self, q: float) -> float:
        """The ``q`` quantile (0..1), within 2.2 % (see the module docstring); NaN when empty."""
        n = self.buckets.sum()
        if n <= 0:
            return math.nan
        rank = max(1.0, math.ceil(q * n))
        k = int(np.searchsorted(np.cumsum(self.buckets), rank))
        if k >= N_BOUNDS:
            return self.maximum
        low = BOUNDS[k - 1] if k else 0.0
        middle = math.sqrt(low * BOUNDS[k]) if low else BOUNDS[k] / 2.0
        return min(middle, self.maximum) if self.maximum > 0 else middle

    def summary(self) -> dict[str, Any]:
        """Count, mean, max and the :data:`QUANTILES`, in seconds (None when empty)."""
        n = self.count
        out: dict[str, Any] = {"count": n, "mean": self.total / n if n else None, "max": self.maximum if n else None}
        for q in QUANTILES:
            out[f"p{q * 100:g}"] = None if not n else self.quantile(q)
        return out

    def samples(self, name: str) -> list[str]:
        """The exposition's sample lines (buckets at every :data:`PROMETHEUS_EVERY`-th bound,
        ``+Inf``, ``_sum``, ``_count``); the family's ``# HELP`` and ``# TYPE`` are the caller's
        (``riderlive.prometheus.Exposition``)."""
        cumulative = np.cumsum(self.buckets)
        lines = [
            sample(f"{name}_bucket", int(cumulative[k]), {"le": BOUNDS[k]})
            for k in range(0, N_BOUNDS, PROMETHEUS_EVERY)
        ]
        lines.append(sample(f"{name}_bucket", int(cumulative[-1]), {"le": "+Inf"}))
        lines.append(sample(f"{name}_sum", self.total))
        lines.append(sample(f"{name}_count", int(cumulative[-1])))
        return lines


def _upper(k: int) -> float:
    return BOUNDS[k] if k < N_BOUNDS else math.inf


TICK_HISTOGRAMS = ("tick_lateness", "ingest_to_wire", "ingest_to_tick")
"""Histograms the tick process fills (in this order in its shared block)."""


def slot_names(histograms: tuple[str, ...]) -> tuple[str, ...]:
    """Names for a :class:`~riderlive.realtime.shm.SharedCounters` block holding ``histograms``."""
    return tuple(f"{h}.{i}" for h in histograms for i in range(SLOTS))


def views(values: np.ndarray, histograms: tuple[str, ...]) -> dict[str, LatencyHistogram]:
    """One :class:`LatencyHistogram` per name over consecutive :data:`SLOTS` of ``values``."""
    return {h: LatencyHistogram(values[i * SLOTS : (i + 1) * SLOTS]) for i, h in enumerate(histograms)}
