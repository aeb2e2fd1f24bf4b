"""Measurements on generated takes, written independently of the generator."""

from __future__ import annotations

import numpy as np

from riderlive.channels import HORSE_INDEX
from riderlive.framefile import FrameTable

LEGS = ("lf", "rf", "lb", "rb")
GROUND = 1e-9


def heights(table: FrameTable) -> np.ndarray:
    """(N, 4) hoof heights in LF, RF, LB, RB order."""
    return np.column_stack([table.values[:, HORSE_INDEX[f"{leg}Hoof.ty"]] for leg in LEGS])


def touchdowns(table: FrameTable, leg: int) -> np.ndarray:
    """Times at which a hoof is placed (in the air one sample, on the ground the next)."""
    down = heights(table)[:, leg] <= GROUND
    idx = np.flatnonzero(down[1:] & ~down[:-1]) + 1
    assert table.t is not None
    return table.t[idx]


def count_runs(mask: np.ndarray) -> int:
    """Number of separate runs of True."""
    return int(np.count_nonzero(mask[1:] & ~mask[:-1]) + (1 if mask[0] else 0))


def oscillations(y: np.ndarray, band: float = 0.25) -> int:
    """Rises through the middle of ``y``'s range, with hysteresis of ``band`` x range each side."""
    mid, span = 0.5 * (y.max() + y.min()), y.max() - y.min()
    hi, lo = mid + band * span, mid - band * span
    count, low = 0, False
    for v in y:
        if v < lo:
            low = True
        elif v > hi and low:
            count += 1
            low = False
    return count


def curvature(values: np.ndarray, rate: float) -> np.ndarray:
    """Per channel: the largest second difference over dt^2 (bounded for a C1 signal)."""
    second = np.abs(values[2:] - 2.0 * values[1:-1] + values[:-2])
    return second.max(axis=0) * rate * rate
