"""Fit a preset to takes: Levenberg-Marquardt on the normal equations, bounded, identified parameters only.

:func:`fit` runs, in order: the coarse clock offset of each take pair
(:mod:`riderlive.fit.offset`); the identifiability analysis at the starting preset
(:mod:`riderlive.fit.identify`); Levenberg-Marquardt (:func:`levenberg_marquardt`) over the
parameters that are identified (or fitted for their group), the rest held at the starting
preset's values; a probe of the clamps the starting preset never reaches (each is shrunk
toward 0 by a few factors and kept where the cost drops: the takes then show the clamp);
the fine clock offset; and the analysis again at the solution, refitting until the set of
fitted parameters settles (a parameter that ends up without effect, or within the noise,
or that ran away along a flat valley, goes back to its starting value).
Uncertainty: ``sqrt(diag((J^T J)^-1) s^2)``, ``s^2`` the weighted residual
variance, per fitted parameter (optimistic when residuals are correlated in time, as
mocap residuals are).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from riderlive.fit import offset as clock
from riderlive.fit.identify import Identification, Status, identify, uncertainty, weak
from riderlive.fit.problem import Aligned, FitInputError, TakePair, align, cost, linearise
from riderlive.fit.vector import Parameter, ParamKind, clamp, from_vector, parameters, ties, to_vector
from riderlive.rules.params import RuleParams

FloatArray = npt.NDArray[np.float64]

PROBE_FACTORS = (0.95, 0.9, 0.8, 0.7, 0.5, 0.3)
"""Factors a clamp without effect is tried at (toward 0: an upper limit comes down, a lower one up)."""
MAX_ROUNDS = 4
"""Rounds of fit and re-analysis at the solution before the set of fitted parameters must have settled."""


@dataclass(frozen=True)
class FitOptions:
    """``drift``: take out each take's translation offsets and trends (mocap); ``search``: largest clock
    offset searched, s (0: none, takes used as timed)."""

    drift: bool = False
    search: float = clock.SEARCH
    max_iterations: int = 100


@dataclass(frozen=True)
class Solution:
    """The fitted preset and what the fit knows about it (see :func:`fit`)."""

    start: RuleParams
    preset: RuleParams
    params: tuple[Parameter, ...]
    start_values: FloatArray
    values: FloatArray
    sigma: FloatArray  # NaN where not fitted
    identification: Identification
    offsets: tuple[float, ...]
    aligned: tuple[Aligned, ...]
    cost: float
    rows: int
    iterations: int
    seconds: float


def levenberg_marquardt(
    takes: Sequence[Aligned],
    start: RuleParams,
    params: Sequence[Parameter],
    x: FloatArray,
    free: Sequence[int],
    *,
    max_iterations: int = 100,
) -> tuple[FloatArray, int]:
    """Minimise :func:`~riderlive.fit.problem.cost` over ``x[free]`` within bounds; (x, iterations)."""
    names = [p.name for p in params]
    held = ties(start)
    x = np.array(x, dtype=np.float64)
    free = list(free)
    if not free:
        return x, 0
    damping = 1e-4
    for iteration in range(1, max_iterations + 1):
        lin = linearise(takes, from_vector(start, names, x), names, held)
        a, g = lin.normal[np.ix_(free, free)], lin.gradient[free]
        diag = np.maximum(np.diag(a), 1e-300)
        while True:
            try:
                step = np.linalg.solve(a + damping * np.diag(diag), -g)
            except np.linalg.LinAlgError:
                damping *= 10.0
                continue
            trial = x.copy()
            trial[free] = x[free] + step
            trial = clamp(trial, params)
            new = cost(takes, from_vector(start, names, trial))
            if new <= lin.cost:
                break
            damping *= 5.0
            if damping > 1e12:
                return x, iteration
        moved = np.abs(trial[free] - x[free])
        x = trial
        damping = max(damping / 5.0, 1e-12)
        if (
            lin.cost - new <= 1e-8 * lin.cost
            or new <= 1e-24 * lin.rows
            or np.all(moved <= 1e-12 * (np.abs(x[free]) + 1e-9))
        ):
            return x, iteration
    return x, max_iterations


def _probe_clamps(
    takes: Sequence[Aligned], start: RuleParams, params: Sequence[Parameter], x: FloatArray, ident: Identification
) -> tuple[FloatArray, bool]:
    """Try each clamp without effect at :data:`PROBE_FACTORS` of its value; keep the best that lowers the cost."""
    names = [p.name for p in params]
    changed = False
    for k, p in enumerate(params):
        if p.kind is not ParamKind.CLAMP or ident.status[k] is not Status.NO_EFFECT or x[k] == 0.0:
            continue
        base = cost(takes, from_vector(start, names, x))
        best, best_cost = x[k], base
        for factor in PROBE_FACTORS:
            trial = x.copy()
            trial[k] = x[k] * factor
            trial = clamp(trial, params)
            c = cost(takes, from_vector(start, names, trial))
            if c < best_cost:
                best, best_cost = trial[k], c
        if best_cost < base * (1.0 - 1e-9):
            x = x.copy()
            x[k] = best
            changed = True
    return x, changed


def fit(pairs: Sequence[TakePair], start: RuleParams, options: FitOptions = FitOptions()) -> Solution:
    """Fit ``start``'s numbers to ``pairs`` (see the module docstring); :class:`FitInputError` when the
    takes cannot be used or identify nothing. BLAS runs on one thread meanwhile: the products are small
    (J^T J blocks of a dozen columns), and threads cost ten times the work on a busy host."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        return _fit(pairs, start, options)


def _fit(pairs: Sequence[TakePair], start: RuleParams, options: FitOptions) -> Solution:
    began = time.perf_counter()
    if not pairs:
        raise FitInputError("no takes to fit")
    for pair in pairs:
        clock.check_overlap(pair, options.search)
    params = parameters(start)
    names = [p.name for p in params]
    held = ties(start)
    x0 = clamp(to_vector(start, names), params)
    offsets = [clock.search(pair, start, options.search) for pair in pairs]
    takes = [align(pair, off, options.drift) for pair, off in zip(pairs, offsets, strict=True)]
    lin = linearise(takes, start, names, held)
    if lin.rows == 0:
        raise FitInputError("no rider frame has a value and a horse frame at its time: nothing to fit")
    ident = identify(lin.normal, x0, lin.rows)
    if not ident.free:
        raise FitInputError(
            f"the takes identify no parameter ({lin.rows} residuals): too short, or the horse does not move"
        )
    x, iterations = levenberg_marquardt(takes, start, params, x0, ident.free, max_iterations=options.max_iterations)
    x, refit = _probe_clamps(takes, start, params, x, ident)
    if options.search > 0.0:
        preset = from_vector(start, names, x)
        refined = [
            clock.refine(p, preset, off, options.drift, options.search) for p, off in zip(pairs, offsets, strict=True)
        ]
        refit = refit or refined != offsets
        offsets = refined
        takes = [align(pair, off, options.drift) for pair, off in zip(pairs, offsets, strict=True)]
    for _ in range(MAX_ROUNDS):
        lin = linearise(takes, from_vector(start, names, x), names, held)
        settled = weak(identify(lin.normal, x, lin.rows), lin.normal, x, lin.cost, lin.rows, start=x0)
        if settled.free == ident.free and not refit:
            break
        refit = False
        ident = settled
        x = np.where([k in ident.free for k in range(len(params))], x, x0)  # never a value the takes do not show
        x, more = levenberg_marquardt(takes, start, params, x, ident.free, max_iterations=options.max_iterations)
        iterations += more
    x = np.where([k in ident.free for k in range(len(params))], x, x0)
    lin = linearise(takes, from_vector(start, names, x), names, held)
    sigma = np.full(len(params), math.nan)
    sigma[ident.free] = uncertainty(lin.normal, ident.free, lin.cost, lin.rows)
    return Solution(
        start=start,
        preset=from_vector(start, names, x),
        params=params,
        start_values=x0,
        values=x,
        sigma=sigma,
        identification=ident,
        offsets=tuple(offsets),
        aligned=tuple(takes),
        cost=lin.cost,
        rows=lin.rows,
        iterations=iterations,
        seconds=time.perf_counter() - began,
    )
