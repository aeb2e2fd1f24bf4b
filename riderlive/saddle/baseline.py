"""The baseline under the measured saddle pose: translations and yaw lose their drift, pitch and roll keep a level.

Pure NumPy on the estimator's history (times in s, the six ``channels.SADDLE`` values,
NaN where an axis was missing). An IMU's translations drift (double-integrated
accelerometers) and so does its heading (an integrated gyro); its pitch and roll are
held by gravity and only read a constant offset (the strap is not level). So:

- translations and yaw: a straight line per channel, the *drift line*. While a gait
  fits, the stride fit's constant and trend (free of the stride's oscillation);
  otherwise a line through the whole history, so that a jump or a rear stays motion.
  For the translations, less the line that the saddle's own rotation about the hips
  explains: pitching up 50 deg in a rear lifts a saddle 0.6 m ahead of the hips by
  0.45 m, and that is motion, not drift. Each new line eases in (smoothstep) over the
  analysis period, so the pose never steps;
- pitch and roll: the *level*, the running mean of the lines' level at first (early
  lines are short and rough), then an exponential mean with time constant
  ``level_time``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt

from riderlive.saddle.pose import ARRAY, SaddlePoint, saddle_from_trunk

FloatArray = npt.NDArray[np.float64]
CHANNELS = 6


@dataclass(frozen=True, slots=True)
class Line:
    """Per channel ``level + slope * (t - t0)``."""

    level: tuple[float, ...]
    slope: tuple[float, ...]
    t0: float

    def at(self, i: int, t: float) -> float:
        return self.level[i] + self.slope[i] * (t - self.t0)


@dataclass(frozen=True, slots=True)
class Drift:
    """The baseline: the line from the last analysis, eased in from the one before over ``blend`` s."""

    line: Line
    prior: Line
    since: float
    blend: float

    def at(self, i: int, t: float) -> float:
        new = self.line.at(i, t)
        u = (t - self.since) / self.blend
        if u >= 1.0:
            return new
        u = max(u, 0.0)
        old = self.prior.at(i, t)
        return old + (new - old) * u * u * (3.0 - 2.0 * u)

    def now(self, t: float) -> Line:
        """The baseline at ``t`` as one line (the start of the next blend)."""
        return Line(tuple(self.at(i, t) for i in range(CHANNELS)), self.line.slope, t)


class Window(Protocol):
    """A stride fit's line: its constant (at ``t``) and trend per channel, over ``span`` s."""

    @property
    def t(self) -> float: ...
    @property
    def span(self) -> float: ...
    @property
    def level(self) -> tuple[float, ...]: ...
    @property
    def slope(self) -> tuple[float, ...]: ...


class Timing(Protocol):
    """The estimator model's two time constants the baseline uses (s)."""

    @property
    def analysis_period(self) -> float: ...
    @property
    def level_time(self) -> float: ...


def baseline(
    times: FloatArray,
    values: FloatArray,
    t: float,
    *,
    window: Window | None,
    point: SaddlePoint,
    drift: Drift | None,
    level: tuple[float, ...] | None,
    levels: int,
    timing: Timing,
) -> tuple[Drift, tuple[float, ...]]:
    """The new drift and level after an analysis at ``t`` (``window``: the fit, while a gait fits).

    ``drift``, ``level`` and ``levels`` (how many lines went into the level) are the
    previous ones.
    """
    tau = times - t
    if window is not None:
        line_level = np.array(window.level) + np.array(window.slope) * (t - window.t)
        slope = np.array(window.slope)
        rows = tau >= -window.span
    else:
        line_level, slope = line(tau, values)
        rows = np.ones(len(tau), dtype=bool)
    a = max(1.0 - math.exp(-timing.analysis_period / timing.level_time), 1.0 / (levels + 1))
    previous = level or tuple(line_level.tolist())
    held = tuple(p + a * (f - p) for p, f in zip(previous, line_level.tolist(), strict=True))
    turns = values[rows][:, 3:] - np.array([held[3], line_level[4], held[5]])  # the rotation that is motion
    turns[:, 1] -= slope[4] * tau[rows]
    valid = np.isfinite(turns).all(axis=1)
    if np.count_nonzero(valid) >= 3:
        r = turns[valid]
        lever = np.column_stack(saddle_from_trunk((0.0, 0.0, 0.0, r[:, 0], r[:, 1], r[:, 2]), 0.0, point, ARRAY)[:3])
        lever_level, lever_slope = line(tau[rows][valid], lever)
        line_level[:3] -= lever_level
        slope[:3] -= lever_slope
    new = Line(tuple(line_level.tolist()), tuple(slope.tolist()), t)
    prior = drift.now(t) if drift is not None else new
    return Drift(new, prior, t, timing.analysis_period), held


def line(tau: FloatArray, values: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Least-squares ``(level at tau = 0, slope)`` per column of ``values`` (NaN rows skipped)."""
    valid = np.isfinite(values)
    w = valid.astype(np.float64)
    v = np.where(valid, values, 0.0)
    s0, s1, s2 = w.sum(axis=0), tau @ w, (tau * tau) @ w
    det = s0 * s2 - s1 * s1
    ok = (s0 >= 3) & (det > 1e-12)
    slope = np.where(ok, (s0 * (tau @ v) - s1 * v.sum(axis=0)) / np.where(ok, det, 1.0), 0.0)
    level = np.where(s0 > 0, (v.sum(axis=0) - slope * s1) / np.maximum(s0, 1.0), 0.0)
    return level, slope
