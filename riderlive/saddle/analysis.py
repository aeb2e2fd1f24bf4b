"""The periodic analysis: the last stride or so of saddle samples -> gait, stride frequency and phase.

Pure NumPy on a short history (times in s, the six ``channels.SADDLE`` values, NaN
where an axis was missing). Three least-squares fits, each with a constant and a
linear trend per channel so that slow drift never enters the harmonics:

1. **Beat**: the vertical (``saddle.ty``) and the pitch (``saddle.rz``) over the last
   ``beat_window`` seconds, one sinusoid each, on a grid of frequencies 2 % apart
   (1.2-3.4 Hz: every gait's vertical), refined by a parabola through the best three.
   The best explains most of both channels' variance: the vertical's dominant
   frequency.
2. **Stride**: every channel with the first two harmonics of the stride, for a stride
   of two beats (walk, trot) and of one beat (canter, gallop), over
   ``window_strides`` of that stride (less while the history is shorter).
3. **Template match**: each gait's template (:mod:`riderlive.saddle.templates`) is
   rotated to the stride phase that correlates best with the measured harmonics. The
   score is that correlation (channels weighted by their typical size), less a
   penalty for a stride frequency outside the gait's published range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from riderlive.horse.gaits import Gait
from riderlive.saddle.templates import CHANNEL_SCALE, WEIGHT, Template, size_of

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]

TAU = 2.0 * math.pi
BEAT_GRID: FloatArray = np.geomspace(1.2, 3.4, 54)
"""Candidate beat frequencies (Hz), 2 % apart."""
NEAR_GRID: FloatArray = np.exp(np.linspace(-0.06, 0.06, 9))
"""Around a locked beat: 9 candidates 1.5 % apart."""
NEAR_EXPLAINED = 0.6
_LOWER = np.tril_indices(4, -1)
PHASES: FloatArray = np.arange(128, dtype=np.float64) / 128.0
RANGE_PENALTY = 4.0
"""Score lost per unit of relative distance outside a gait's stride frequency range."""
BEAT_SAMPLES = 96
STRIDE_SAMPLES = 160
"""At most this many samples enter a fit (every k-th of a denser history)."""


@dataclass(frozen=True, slots=True)
class Fit:
    """One analysis: what the history says at its last sample's time ``t`` (s).

    ``gait`` is the best match (None when the saddle is still or nothing fits);
    ``stride`` (Hz) and ``phase`` (strides, 0-1, at ``t``) are that gait's; ``score``
    its correlation with the template after the range penalty (-1..1); ``size`` the
    measured harmonics' size against the template's; ``level`` and ``slope`` each
    channel's fitted constant (at ``t``) and trend (per s) for drift removal;
    ``smooth`` the residual's lag-1 autocorrelation (about 0 for white noise);
    ``span`` the stride fit's window (s); ``half`` that the phase is known only modulo
    half a stride (a two-beat gait without the sideways axes that tell its diagonals apart).
    """

    t: float
    beat: float
    gait: Gait | None
    stride: float
    phase: float
    score: float
    size: float
    level: tuple[float, ...]
    slope: tuple[float, ...]
    smooth: float
    span: float = 0.0
    half: bool = False
    scores: tuple[tuple[Gait, float], ...] = ()


def _design(tau: FloatArray, frequency: float, harmonics: int) -> FloatArray:
    columns = [np.ones_like(tau), tau]
    for k in range(1, harmonics + 1):
        angle = TAU * k * frequency * tau
        columns += [np.cos(angle), np.sin(angle)]
    return np.column_stack(columns)


def _solve(x: FloatArray, y: FloatArray, mask: npt.NDArray[np.bool_]) -> tuple[FloatArray, FloatArray]:
    """Least squares of every channel of ``y`` (N, C) on its valid rows against ``x`` (N, P).

    Returns the coefficients (C, P) and the sum of squares each fit explains (C,).
    Channels with the same valid rows (all of them, usually) share one solve.
    """
    beta = np.zeros((y.shape[1], x.shape[1]))
    explained = np.zeros(y.shape[1])
    groups: dict[bytes, list[int]] = {}
    for c in range(y.shape[1]):
        groups.setdefault(mask[:, c].tobytes(), []).append(c)
    for channels in groups.values():
        rows = mask[:, channels[0]]
        if np.count_nonzero(rows) <= x.shape[1]:
            continue  # too few samples of this axis: it says nothing
        xr = x[rows]
        gram = xr.T @ xr
        gram += np.eye(x.shape[1]) * (1e-12 * np.trace(gram))
        rhs = xr.T @ y[rows][:, channels]
        b = np.linalg.solve(gram, rhs)
        beta[channels] = b.T
        explained[channels] = np.sum(b * rhs, axis=0)
    return beta, explained


def beat_frequency(
    tau: FloatArray,
    y: FloatArray,
    mask: npt.NDArray[np.bool_],
    grid: FloatArray = BEAT_GRID,
) -> tuple[float, float]:
    """``(Hz, fraction of variance explained)`` of the strongest sinusoid in ``y`` (N, C) over ``grid``.

    Every candidate's 4x4 normal equations (constant, trend, cosine, sine) come from a
    few matrix-vector products over all candidates at once.
    """
    angle = TAU * grid[:, None] * tau[None, :]  # (J, N)
    cos, sin = np.cos(angle), np.sin(angle)
    w = mask.astype(np.float64)  # (N, C)
    used = np.count_nonzero(w, axis=0) >= 8
    v = np.where(mask, y, 0.0)
    wt = w * tau[:, None]
    s0, s1, s2 = w.sum(axis=0), tau @ w, tau @ wt  # (C,)
    sy, sty, syy = np.sum(w * v, axis=0), np.sum(wt * v, axis=0), np.sum(w * v * v, axis=0)
    det = np.where(used, s0 * s2 - s1 * s1, 1.0)
    base_ss = (s2 * sy * sy - 2.0 * s1 * sy * sty + s0 * sty * sty) / det  # explained by constant and trend
    total = np.maximum(syy - base_ss, 1e-30)
    columns = np.concatenate([w, wt, w * v], axis=1)  # (N, 3C)
    c_sums, s_sums = cos @ columns, sin @ columns  # (J, 3C)
    cc, cs = (cos * cos) @ w, (cos * sin) @ w  # (J, C)
    n, channels = len(grid), y.shape[1]
    gram = np.empty((n, channels, 4, 4))
    gram[..., 0, 0], gram[..., 0, 1], gram[..., 1, 1] = s0, s1, s2
    gram[..., 0, 2], gram[..., 0, 3] = c_sums[:, :channels], s_sums[:, :channels]
    gram[..., 1, 2], gram[..., 1, 3] = c_sums[:, channels : 2 * channels], s_sums[:, channels : 2 * channels]
    gram[..., 2, 2], gram[..., 3, 3], gram[..., 2, 3] = cc, s0 - cc, cs
    gram[..., _LOWER[0], _LOWER[1]] = gram[..., _LOWER[1], _LOWER[0]]
    gram += np.eye(4) * (1e-12 * np.maximum(s0, 1e-12))[:, None, None]
    rhs = np.empty((n, channels, 4))
    rhs[..., 0], rhs[..., 1] = sy, sty
    rhs[..., 2], rhs[..., 3] = c_sums[:, 2 * channels :], s_sums[:, 2 * channels :]
    beta = np.linalg.solve(gram, rhs[..., None])[..., 0]
    explained = (np.sum(beta * rhs, axis=-1) - base_ss) / total  # (J, C)
    score = np.sum(np.where(used, explained, 0.0), axis=1) / max(channels, 1)
    best = int(np.argmax(score))
    frequency = float(grid[best])
    if 0 < best < len(grid) - 1:
        s_lo, s_mid, s_hi = score[best - 1], score[best], score[best + 1]
        denominator = s_lo - 2.0 * s_mid + s_hi
        if denominator < 0.0:
            step = math.log(grid[best + 1] / grid[best])
            frequency *= math.exp(0.5 * step * (s_lo - s_hi) / denominator)
    return frequency, float(score[best])


@dataclass(frozen=True, slots=True)
class StrideFit:
    """Harmonics (6, 2) at the window's end, constant and slope per channel, residual smoothness."""

    harmonics: ComplexArray
    level: FloatArray
    slope: FloatArray
    smooth: float


def stride_fit(tau: FloatArray, y: FloatArray, mask: npt.NDArray[np.bool_], stride: float) -> StrideFit:
    """The first two harmonics of ``stride`` (Hz) in every channel, referred to ``tau = 0``."""
    x = _design(tau, stride, 2)
    beta, _ = _solve(x, y, mask)
    harmonics = (beta[:, 2::2] - 1j * beta[:, 3::2]).astype(np.complex128)
    residual = np.where(mask, y - x @ beta.T, 0.0)
    r = residual[:, [1, 5]] / CHANNEL_SCALE[[1, 5]]
    energy = float(np.sum(r * r))
    smooth = float(np.sum(r[1:] * r[:-1]) / energy) if energy > 0.0 else 1.0
    return StrideFit(harmonics, beta[:, 0].copy(), beta[:, 1].copy(), smooth)


_WAVES: FloatArray = np.stack(
    [np.cos(TAU * PHASES), np.sin(TAU * PHASES), np.cos(2.0 * TAU * PHASES), np.sin(2.0 * TAU * PHASES)]
)


@dataclass(frozen=True, slots=True)
class Match:
    """A template against measured harmonics: score (-1..1, less the range penalty), phase, size, ``half``."""

    score: float
    phase: float
    size: float
    half: bool


HALF_SHARE = 0.05
"""Below this share of once-per-stride evidence, a two-beat gait's phase is known modulo half a stride."""


def match(harmonics: ComplexArray, template: Template, stride: float) -> Match:
    """The template rotated to its best stride phase against ``harmonics``."""
    t = template.harmonics
    cross = WEIGHT @ (harmonics * np.conj(t))  # (2,): sum over channels
    curve = np.array([cross[0].real, cross[0].imag, cross[1].real, cross[1].imag]) @ _WAVES
    best = int(np.argmax(curve))
    phase = float(PHASES[best])
    c0, c1, c2 = curve[best - 1], curve[best], curve[(best + 1) % len(PHASES)]
    denominator = c0 - 2.0 * c1 + c2
    if denominator < 0.0:
        phase += 0.5 * float(c0 - c2) / float(denominator) / len(PHASES)
    turn = np.exp(-1j * TAU * phase)
    value = (cross[0] * turn + cross[1] * turn * turn).real
    measured, expected = size_of(harmonics), template.size
    score = float(value) / max(measured * expected, 1e-30)
    lo, hi = template.spec.frequency
    outside = max(0.0, (lo - stride) / lo, (stride - hi) / hi)
    half = template.beats == 2 and abs(cross[0]) < HALF_SHARE * (abs(cross[0]) + abs(cross[1]))
    return Match(score - RANGE_PENALTY * outside, phase % 1.0, measured / expected, bool(half))


def _thin(rows: npt.NDArray[np.bool_], most: int) -> npt.NDArray[np.intp]:
    """Indices of ``rows``, every k-th so that at most ``most`` remain (the newest kept)."""
    index = np.flatnonzero(rows)
    step = -(-len(index) // most)
    return index[::-1][::step][::-1]


def analyse(
    times: FloatArray,
    values: FloatArray,
    templates: dict[Gait, Template],
    *,
    window_strides: float = 1.25,
    beat_window: float = 1.2,
    min_strides: float = 0.9,
    min_beats: float = 1.1,
    quiet: float = 0.15,
    current: Gait | None = None,
    stay: float = 0.03,
    near: float | None = None,
    sure: float = 0.85,
    changed_window: float = 0.6,
) -> Fit | None:
    """Analyse a history (``times`` increasing, ``values`` (N, 6) with NaN for missing axes).

    None when the history is too short for even the beat. ``current`` (the gait the
    caller is locked to) gets ``stay`` of score as hysteresis; ``near`` (its beat, Hz)
    narrows the beat search to within 6 % of it while that explains the motion well,
    and then the other stride (one beat or two) is tried only if the current gait
    scores below ``sure``.
    """
    if len(times) < 8:
        return None
    t_end = float(times[-1])
    tau = times - t_end
    mask = np.isfinite(values)
    recent = _thin(tau >= -beat_window, BEAT_SAMPLES)
    seen = -float(tau[recent[0]])
    if seen < min_beats / BEAT_GRID[-1]:
        return None
    vertical = values[recent][:, [1, 5]] / CHANNEL_SCALE[[1, 5]]
    beat = 0.0
    hypotheses: tuple[int, ...] = (2, 1)
    if near is not None and current is not None:  # locked: look around the locked beat first
        grid = near * NEAR_GRID
        beat, explained = beat_frequency(tau[recent], vertical, mask[recent][:, [1, 5]], grid)
        if grid[0] < beat < grid[-1] and explained >= NEAR_EXPLAINED:
            hypotheses = (templates[current].beats,)  # the other stride only if this one fails (below)
        else:  # the motion changed: judge by the newest samples only
            beat = 0.0
            recent = recent[tau[recent] >= -changed_window]
            vertical = values[recent][:, [1, 5]] / CHANNEL_SCALE[[1, 5]]
    if beat == 0.0:
        beat, _ = beat_frequency(tau[recent], vertical, mask[recent][:, [1, 5]])
    if seen < min_beats / beat:
        return None
    span = -float(tau[0])
    best: tuple[float, Gait | None, float, Match | None, StrideFit | None, float] = (
        -math.inf,
        None,
        beat,
        None,
        None,
        0.0,
    )
    scores: list[tuple[Gait, float]] = []
    activity = 0.0
    if len(hypotheses) == 1:
        hypotheses = (hypotheses[0], 3 - hypotheses[0])  # the other only if the locked gait fits badly
    for beats in hypotheses:
        if beats != hypotheses[0] and near is not None and best[1] is current and best[0] - stay >= sure:
            break
        stride = beat / beats
        if span < min_strides / stride:
            continue
        window = min(window_strides / stride, span)
        rows = _thin(tau >= -window, STRIDE_SAMPLES)
        fit = stride_fit(tau[rows], values[rows], mask[rows], stride)
        if best[4] is None:
            best = (-math.inf, None, stride, None, fit, window)
        for template in templates.values():
            if template.beats != beats:
                continue
            found = match(fit.harmonics, template, stride)
            activity = max(activity, found.size * template.size)
            scores.append((template.gait, found.score))
            ranked = found.score + (stay if template.gait is current else 0.0)
            if ranked > best[0]:
                best = (ranked, template.gait, stride, found, fit, window)
    _, gait, stride, best_match, best_fit, window = best
    if best_fit is None:
        return None
    fit = best_fit
    found = best_match if best_match is not None and activity >= quiet else Match(0.0, 0.0, 0.0, False)
    if best_match is None or activity < quiet:
        gait = None
    return Fit(
        t=t_end,
        beat=beat,
        gait=gait,
        stride=stride,
        phase=found.phase,
        score=found.score,
        size=found.size,
        level=tuple(fit.level.tolist()),
        slope=tuple(fit.slope.tolist()),
        smooth=fit.smooth,
        span=window,
        half=found.half,
        scores=tuple(scores),
    )
