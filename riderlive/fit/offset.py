"""The clock offset between a horse take and its rider take, within +-:data:`SEARCH` seconds.

Coarse (:func:`search`): the starting preset's prediction on the horse's own frames is
read at the rider's times plus each candidate offset (one horse frame apart), and the
candidate whose prediction correlates best with the rider (sum over channels of r^2: gains
that are off, even of the wrong sign, do not move the peak) wins, a whole number of horse
frames (every fourth frame first, then every frame around the best). Fine (:func:`refine`): with the fitted
preset, the offset that minimises the fit's cost within a frame or two of the coarse one.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.optimize import minimize_scalar

from riderlive.channels import RIDER_INDEX
from riderlive.fit.problem import FitInputError, TakePair, align, cost, overlap
from riderlive.rules.engine import RiderModel
from riderlive.rules.params import RuleParams

FloatArray = npt.NDArray[np.float64]

SEARCH = 0.5
"""The largest clock offset searched, seconds."""
COARSE_STRIDE = 4
"""Horse frames between the candidates of the first pass (the second tries every frame around the best)."""
IMPROVEMENT = 1e-6
"""Relative drop of the cost that moves the offset off the coarse one ..."""
FLOOR = 1e-12
"""... and absolute drop per residual (weighted units squared: 1e-6 degree RMS), below which it is rounding."""
MIN_OVERLAP = 1.0
"""Seconds both takes must share at every candidate offset."""


def _frame_step(pair: TakePair) -> float:
    dt = np.diff(pair.horse.t)
    return float(np.median(dt)) if len(dt) else 0.0


def check_overlap(pair: TakePair, search: float) -> None:
    """Raise :class:`FitInputError` unless the takes share :data:`MIN_OVERLAP` s at every offset within ``search``."""
    for take, t in ((pair.horse.name, pair.horse.t), (pair.rider.name, pair.rider.t)):
        if t[-1] - t[0] < MIN_OVERLAP:
            raise FitInputError(
                f"{take} is too short to identify anything: {t[-1] - t[0]:.3f} s (at least {MIN_OVERLAP:g} s)"
            )
    for offset in (-search, 0.0, search):
        start, stop = overlap(pair, offset)
        if stop - start < MIN_OVERLAP:
            raise FitInputError(
                f"{pair.horse.name} and {pair.rider.name} do not overlap in time: horse "
                f"{pair.horse.t[0]:.3f}-{pair.horse.t[-1]:.3f} s, rider {pair.rider.t[0]:.3f}-{pair.rider.t[-1]:.3f} s "
                f"(need {MIN_OVERLAP:g} s in common at every offset within +-{search:g} s)"
            )


def search(pair: TakePair, preset: RuleParams, limit: float = SEARCH) -> float:
    """The coarse offset (s, rider clock + offset = horse clock) of ``pair`` (see the module docstring)."""
    step = _frame_step(pair)
    if limit <= 0.0 or step <= 0.0:
        return 0.0
    horse, rider = pair.horse, pair.rider
    model = RiderModel(params=preset, scale=horse.scale)
    predicted = model.evaluate_columns(dict(horse.columns), len(horse.t), compiled=False)
    predicted = predicted[:, [RIDER_INDEX[n] for n in rider.names]]
    frames = int(np.floor(limit / step))
    coarse = np.arange(-frames, frames + 1, COARSE_STRIDE)
    best = _best(pair, predicted, coarse, step)
    fine = np.arange(max(-frames, best - COARSE_STRIDE + 1), min(frames, best + COARSE_STRIDE - 1) + 1)
    return _best(pair, predicted, fine, step) * step


def _best(pair: TakePair, predicted: FloatArray, frames: npt.NDArray[np.int_], step: float) -> int:
    """The candidate of ``frames`` (whole horse frames) that scores best."""
    scores = np.array([_score(pair, predicted, float(f) * step) for f in frames])
    return int(frames[int(np.argmax(scores))])


def _score(pair: TakePair, predicted: FloatArray, offset: float) -> float:
    """Sum over channels of the squared correlation of the prediction read at rider time + ``offset``."""
    horse, rider = pair.horse, pair.rider
    at = rider.t + offset
    inside = (at >= horse.t[0]) & (at <= horse.t[-1])
    at = at[inside]
    upper = np.clip(np.searchsorted(horse.t, at), 1, len(horse.t) - 1)
    span = horse.t[upper] - horse.t[upper - 1]
    w = np.where(span > 0.0, (at - horse.t[upper - 1]) / np.where(span > 0.0, span, 1.0), 0.0)[:, None]
    x = predicted[upper - 1] * (1.0 - w) + predicted[upper] * w  # (n, C): every channel at once
    y = rider.values[inside]
    m = np.isfinite(y)
    y = np.where(m, y, 0.0)
    n = np.maximum(m.sum(axis=0), 1)
    x = (x - (x * m).sum(axis=0) / n) * m
    y = (y - y.sum(axis=0) / n) * m
    denominator = np.sqrt((x * x).sum(axis=0) * (y * y).sum(axis=0))
    r = np.divide((x * y).sum(axis=0), denominator, out=np.zeros_like(denominator), where=denominator > 0.0)
    return float((r * r).sum())


def refine(pair: TakePair, preset: RuleParams, coarse: float, drift: bool, limit: float = SEARCH) -> float:
    """The offset within one horse frame of ``coarse`` (and within +-``limit``) minimising the fit's cost:
    a bounded Brent search, against the coarse offset and the whole-frame offsets in range (where
    interpolation adds no error of its own)."""
    step = _frame_step(pair)
    if limit <= 0.0 or step <= 0.0:
        return coarse
    low, high = max(-limit, coarse - step), min(limit, coarse + step)
    result = minimize_scalar(
        lambda offset: cost([align(pair, float(offset), drift)], preset),
        bounds=(low, high),
        method="bounded",
        options={"xatol": 1e-2 * step},
    )
    candidates = [float(result.x), coarse, *(np.round(np.array([low, high, coarse]) / step) * step)]
    costs = [cost([align(pair, c, drift)], preset) if low <= c <= high or c == coarse else np.inf for c in candidates]
    best = int(np.argmin(costs))
    rows = int(align(pair, coarse, drift).valid.sum())
    return candidates[best] if costs[best] < costs[1] - max(IMPROVEMENT * costs[1], FLOOR * rows) else coarse
