"""Which parameters the takes identify, from J^T J at a point.

- **no effect** (:attr:`Status.NO_EFFECT`): changing the parameter by its own size (or by 1
  when it is 0) moves no residual: its input never moves, or its clamp is never reached.
  Held at the starting preset's value.
- **confounded**: the parameter lies in a null direction of the column-normalised J^T J
  with others (only a combination is identified: ``squash.offset`` with the rest heights,
  or the product ``pivot_rotation_weight * front_height_weight * height_term_weight``).
  Going through the parameters in preset order, each one that adds a direction is fitted
  (:attr:`Status.FITTED_IN_GROUP`: its value is the group's combination given the others
  held) and the rest are held (:attr:`Status.HELD_IN_GROUP`).
- **identified** (:attr:`Status.IDENTIFIED`): in no null direction.
- **within the noise** (:attr:`Status.WEAK`, by :func:`weak` after a fit): identified in
  principle, but its uncertainty is above :data:`WEAK_UNCERTAINTY` of its value (a gain of
  0.0001 under millimetres of noise), or the fit took it more than :data:`RUNAWAY` scales
  from the starting preset (the takes barely pin it and it ran along a flat valley). Held
  at the starting preset's value.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

EFFECT_TOLERANCE = 1e-8
"""Weighted RMS residual change (per row) below which a parameter changed by its own size has no effect."""
NULL_TOLERANCE = 1e-10
"""Eigenvalue of the column-normalised J^T J (unit diagonal) below which its direction is a null direction."""
WEAK_UNCERTAINTY = 0.01
"""Uncertainty, relative to the value (at least :data:`WEAK_FLOOR`), above which a fitted parameter is held."""
WEAK_FLOOR = 1e-3
RUNAWAY = 10.0
"""A fitted value this many scales (the starting value's magnitude, at least 1) from the
starting preset's is not what the takes show but a run along a flat valley: ``child`` under
mocap noise took ``wrists.back_gain`` from 0.0001 to -1173 or -8816 and ``back_limit`` from
17 to -3e8 or -2.6e9, by the BLAS kernel (Haswell or AVX-512, 2026-11-28); the relative
uncertainty then read 67 % or 0.76 %, on either side of :data:`WEAK_UNCERTAINTY`. The largest
move of the recovery cases (4 presets, clean and under mocap noise) is 1.4 scales:
``head.lift_gain`` from 10 to 24."""
MEMBER_TOLERANCE = 1e-6
"""Entry of the projector onto the null space above which two parameters are linked."""


class Status(enum.Enum):
    IDENTIFIED = "identified"
    FITTED_IN_GROUP = "fitted in a group (only a combination is identified)"
    HELD_IN_GROUP = "not identified: held (confounded with others)"
    NO_EFFECT = "not identified: no effect in the takes (input never moves, clamp never reached)"
    WEAK = "not identified: within the noise (uncertainty above 1 % of the value)"


@dataclass(frozen=True)
class Identification:
    """``status`` per parameter; ``groups[k]``: the other parameters ``k`` is confounded with."""

    status: tuple[Status, ...]
    groups: tuple[tuple[int, ...], ...]

    @property
    def free(self) -> list[int]:
        """The parameters the fit moves."""
        return [k for k, s in enumerate(self.status) if s in (Status.IDENTIFIED, Status.FITTED_IN_GROUP)]


def identify(normal: FloatArray, values: FloatArray, rows: int, order: Sequence[int] | None = None) -> Identification:
    """Classify each parameter from ``normal`` = J^T J at ``values`` over ``rows`` residuals."""
    p = len(values)
    size = np.maximum(np.abs(values), 1.0 * (values == 0.0) + 1e-12)
    diag = np.clip(np.diag(normal), 0.0, None)
    effect = np.sqrt(diag / max(rows, 1)) * size
    moving = [k for k in range(p) if effect[k] > EFFECT_TOLERANCE]
    status = [Status.NO_EFFECT] * p
    groups: list[tuple[int, ...]] = [()] * p
    if not moving:
        return Identification(tuple(status), tuple(groups))
    d = np.sqrt(diag[moving])
    gram = normal[np.ix_(moving, moving)] / np.outer(d, d)
    eigenvalues, vectors = np.linalg.eigh(gram)
    null = vectors[:, eigenvalues < NULL_TOLERANCE * max(1.0, float(eigenvalues[-1]))]
    # confounded parameters: linked through the projector onto the null space (independent of its basis)
    projector = null @ null.T
    linked = {
        k: set(np.flatnonzero(np.abs(projector[k]) > MEMBER_TOLERANCE).tolist()) - {k} for k in range(len(moving))
    }
    kept: list[int] = []
    for local in order_of(moving, order):
        if not linked[local]:
            status[moving[local]] = Status.IDENTIFIED
            kept.append(local)
            continue
        trial = [*kept, local]
        sub = gram[np.ix_(trial, trial)]
        smallest = float(np.linalg.eigvalsh(sub)[0])
        if smallest > NULL_TOLERANCE * len(trial):
            kept.append(local)
            status[moving[local]] = Status.FITTED_IN_GROUP
        else:
            status[moving[local]] = Status.HELD_IN_GROUP
        groups[moving[local]] = tuple(sorted(moving[o] for o in _component(linked, local)))
    return Identification(tuple(status), tuple(groups))


def order_of(moving: Sequence[int], order: Sequence[int] | None) -> list[int]:
    """Local indices of ``moving`` in the preference ``order`` (global indices; default: preset order)."""
    if order is None:
        return list(range(len(moving)))
    rank = {g: i for i, g in enumerate(order)}
    return sorted(range(len(moving)), key=lambda local: rank.get(moving[local], len(rank)))


def _component(linked: dict[int, set[int]], start: int) -> set[int]:
    seen, todo = {start}, [start]
    while todo:
        for other in linked[todo.pop()] - seen:
            seen.add(other)
            todo.append(other)
    return seen - {start}


def uncertainty(normal: FloatArray, free: Sequence[int], cost: float, rows: int) -> FloatArray:
    """One standard deviation per parameter of ``free`` (preset units): ``sqrt(diag((J^T J)^-1) s^2)`` with
    ``s^2`` the weighted residual variance ``2 cost / (rows - len(free))``."""
    if not free:
        return np.zeros(0)
    sub = normal[np.ix_(free, free)]
    d = np.sqrt(np.diag(sub))
    inverse = np.linalg.pinv(sub / np.outer(d, d)) / np.outer(d, d)
    variance = 2.0 * cost / max(rows - len(free), 1)
    return np.sqrt(np.clip(np.diag(inverse), 0.0, None) * variance)


def weak(
    ident: Identification,
    normal: FloatArray,
    values: FloatArray,
    cost: float,
    rows: int,
    *,
    start: FloatArray | None = None,
) -> Identification:
    """``ident`` with each identified parameter whose uncertainty at the fitted ``values`` (``cost`` over
    ``rows``) exceeds :data:`WEAK_UNCERTAINTY` of its value, or which lies more than :data:`RUNAWAY`
    scales from its ``start`` value, marked :attr:`Status.WEAK`. A parameter fitted for its group stays:
    its value stands for the group's combination, which holding it would get wrong."""
    free = ident.free
    sigma = uncertainty(normal, free, cost, rows)
    status = list(ident.status)
    for k, s in zip(free, sigma, strict=True):
        value = float(values[k])
        ran = start is not None and abs(value - start[k]) > RUNAWAY * max(abs(float(start[k])), 1.0)
        if status[k] is Status.IDENTIFIED and (ran or s > WEAK_UNCERTAINTY * max(abs(value), WEAK_FLOOR)):
            status[k] = Status.WEAK
    return Identification(tuple(status), ident.groups)
