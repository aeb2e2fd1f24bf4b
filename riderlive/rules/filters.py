"""The animator's filters over a whole take, compiled from the live path's one source.

:func:`riderlive.rules.animator.damp_exact` and :func:`~riderlive.rules.animator.spring_exact`
are the steps the live tick runs on a frame's channel vector; here
:func:`riderlive.fastpath.kernel` compiles them, channel by channel over rows of frames,
in place and in pieces that carry the filter's state (:func:`damp_rows`,
:func:`spring_rows`; a streamed bake filters one chunk at a time). A module of its own so
that importing the rules does not import numba (about a second); the bake does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from riderlive.fastpath import inline, kernel
from riderlive.rules.animator import FloatArray, damp_exact, spring_exact, spring_rates

inline(damp_exact)  # compiled into the kernels below; Python callers get the function unchanged
inline(spring_exact)


@dataclass(frozen=True, slots=True)
class SeriesState:
    """Where a filter over rows of frames stopped: each channel's value and velocity, and that frame's time (s)."""

    value: FloatArray
    velocity: FloatArray
    time: float


def damp_rows(
    rows: FloatArray, times: FloatArray, time_constant: float, state: SeriesState | None = None
) -> SeriesState | None:
    """Smooth ``rows`` (C, N; C-contiguous, one row per channel) in place; ``times`` is (N,) seconds.

    ``state``: where the previous piece of the take stopped (None: start at rest on the first
    frame). Returns the state after the last frame (None for an empty piece with no state).
    ``time_constant`` <= 0: the rows pass unchanged.
    """
    if time_constant <= 0.0:
        return _rest(rows, times, state)
    if rows.shape[1] == 0:
        return state
    value, velocity, last = _start(rows, times, state)
    _damp_kernel(rows, np.ascontiguousarray(times, dtype=np.float64), last, 1.0 / time_constant, value, velocity)
    return SeriesState(value, velocity, float(times[-1]))


@kernel
def _damp_kernel(  # noqa: PLR0917
    rows: FloatArray, times: FloatArray, last: float, omega: float, value: FloatArray, velocity: FloatArray
) -> None:
    for i in range(times.shape[0]):  # frame by frame, the channels side by side (independent, so they overlap)
        dt = times[i] - (last if i == 0 else times[i - 1])
        if dt > 0.0:
            decay = math.exp(-omega * dt)
            for c in range(rows.shape[0]):
                value[c], velocity[c] = damp_exact(value[c], velocity[c], rows[c, i], dt, omega, decay)
                rows[c, i] = value[c]
        else:
            for c in range(rows.shape[0]):
                value[c], velocity[c] = rows[c, i], 0.0


def _start(rows: FloatArray, times: FloatArray, state: SeriesState | None) -> tuple[FloatArray, FloatArray, float]:
    """The state's arrays (copied) and time, or at rest on the first frame."""
    if not (rows.flags.c_contiguous and rows.dtype == np.float64 and rows.ndim == 2):
        raise ValueError("rows must be a C-contiguous (C, N) float64 array")
    if len(times) != rows.shape[1]:
        raise ValueError(f"{rows.shape[1]} frames but {len(times)} times")
    if state is None:
        return rows[:, 0].copy(), np.zeros(rows.shape[0]), float(times[0])
    return state.value.copy(), state.velocity.copy(), state.time


def _rest(rows: FloatArray, times: FloatArray, state: SeriesState | None) -> SeriesState | None:
    """A filter that is off: at rest on the last frame."""
    if rows.shape[1] == 0:
        return state
    return SeriesState(rows[:, -1].copy(), np.zeros(rows.shape[0]), float(times[-1]))


def damp_series(values: FloatArray, times: FloatArray, time_constant: float) -> FloatArray:
    """Run the follower over a whole take: ``values`` is (N, C), ``times`` is (N,); a new (N, C) array."""
    rows = np.array(values.T, dtype=np.float64, order="C")
    damp_rows(rows, times, time_constant)
    return rows.T


def spring_rows(
    rows: FloatArray, times: FloatArray, frequency: float, damping: float, state: SeriesState | None = None
) -> SeriesState | None:
    """The follow-through on ``rows`` (C, N) in place, in pieces like :func:`damp_rows`; 0 Hz: unchanged."""
    if frequency <= 0.0:
        return _rest(rows, times, state)
    if rows.shape[1] == 0:
        return state
    value, velocity, last = _start(rows, times, state)
    omega, decay_rate, omega_d = spring_rates(frequency, damping)
    _spring_kernel(
        rows, np.ascontiguousarray(times, dtype=np.float64), last, omega, decay_rate, omega_d, value, velocity
    )
    return SeriesState(value, velocity, float(times[-1]))


@kernel
def _spring_kernel(  # noqa: PLR0917
    rows: FloatArray,
    times: FloatArray,
    last: float,
    omega: float,
    decay_rate: float,
    omega_d: float,
    value: FloatArray,
    velocity: FloatArray,
) -> None:
    for i in range(times.shape[0]):  # frame by frame, the channels side by side
        dt = times[i] - (last if i == 0 else times[i - 1])
        if dt > 0.0:
            decay = math.exp(-decay_rate * dt)
            c, s = math.cos(omega_d * dt), math.sin(omega_d * dt)
            for j in range(rows.shape[0]):
                value[j], velocity[j] = spring_exact(
                    value[j], velocity[j], rows[j, i], omega, decay_rate, omega_d, decay, c, s
                )
                rows[j, i] = value[j]
        else:
            for j in range(rows.shape[0]):
                value[j], velocity[j] = rows[j, i], 0.0


def spring_series(values: FloatArray, times: FloatArray, frequency: float, damping: float) -> FloatArray:
    """Run the follow-through over a whole take: ``values`` is (N, C), ``times`` is (N,); a new (N, C) array."""
    rows = np.array(values.T, dtype=np.float64, order="C")
    spring_rows(rows, times, frequency, damping)
    return rows.T
