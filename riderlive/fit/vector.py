"""The fitted parameters of a preset as a vector, with bounds, and back.

Every number the rules read (:func:`riderlive.rules.kuhnel2003.make_rules`) and the
``[terrain]`` lean is a candidate: the groups of :data:`FIT_GROUPS`, each field of
:class:`~riderlive.rules.params.RuleParams` in declaration order. Not fitted, held at the
starting preset's value and listed as such in the report: ``[errata]`` (readings of
Appendix B, chosen, not measured), ``[smoothing]`` and ``[follow_through]`` (filters over
time), ``[reins]``, ``[arms]`` and ``[stirrups]`` (rider parts, not rider channels).

Bounds come from the preset model's own constraints (pydantic ``ge`` / ``le``); a divisor
(``squash.*_divisor``, which must not be zero) keeps the starting value's sign. Values
and bounds are in the preset's units (thesis rig units, degrees).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass

import annotated_types
import numpy as np
import numpy.typing as npt

from riderlive.rules.params import RuleParams

FloatArray = npt.NDArray[np.float64]

FIT_GROUPS: tuple[str, ...] = (
    "lower_back",
    "waist",
    "hip",
    "lift",
    "seat_shift",
    "squash",
    "head",
    "wrists",
    "feet",
    "knees",
    "hair_cloth",
    "terrain",
)
"""The preset tables whose numbers are fitted."""

HELD_GROUPS: tuple[str, ...] = ("errata", "smoothing", "follow_through", "reins", "arms", "stirrups")
"""The preset tables held at the starting preset's values (see the module docstring)."""

TIES: dict[str, str] = {"errata.left_foot_clamped_belly_pivot_gain": "feet.belly_pivot_gain"}
"""Held keys that follow a fitted key when they were equal in the starting preset: the reading
"the left foot's clamped branch uses the same gain" stays that reading."""

DIVISORS: frozenset[str] = frozenset({"squash.spine_divisor", "squash.neck_divisor"})
DIVISOR_MARGIN = 1e-6
"""A divisor's bound on the side of zero: it keeps its starting sign."""


class ParamKind(enum.Enum):
    """What a parameter does in the rules, which decides how a take identifies it."""

    WEIGHT = "weight"  # multiplies an input (or another term)
    OFFSET = "offset"  # added to a term, or a rest value
    CLAMP = "clamp"  # a limit a term is held within


def kind_of(name: str) -> ParamKind:
    """The kind of parameter ``name`` (``group.key``), from its key."""
    key = name.split(".", 1)[1]
    if "limit" in key or key.endswith(("_max", "_min")):
        return ParamKind.CLAMP
    if "offset" in key or key.startswith("rest_"):
        return ParamKind.OFFSET
    return ParamKind.WEIGHT


@dataclass(frozen=True, slots=True)
class Parameter:
    """One fitted number: ``name`` is ``group.key``; ``lower`` / ``upper`` bound it (may be infinite)."""

    name: str
    kind: ParamKind
    lower: float
    upper: float


def _field_bounds(group: str, key: str) -> tuple[float, float]:
    model = type(getattr(RuleParams(), group))
    lower, upper = -math.inf, math.inf
    for meta in model.model_fields[key].metadata:
        if isinstance(meta, annotated_types.Ge):
            lower = float(meta.ge)  # type: ignore[arg-type]
        elif isinstance(meta, annotated_types.Gt):
            lower = float(meta.gt)  # type: ignore[arg-type]
        elif isinstance(meta, annotated_types.Le):
            upper = float(meta.le)  # type: ignore[arg-type]
        elif isinstance(meta, annotated_types.Lt):
            upper = float(meta.lt)  # type: ignore[arg-type]
    return lower, upper


def parameters(start: RuleParams) -> tuple[Parameter, ...]:
    """Every fitted parameter, in preset order, bounded (a divisor on ``start``'s side of zero)."""
    out: list[Parameter] = []
    for group in FIT_GROUPS:
        for key in type(getattr(start, group)).model_fields:
            name = f"{group}.{key}"
            lower, upper = _field_bounds(group, key)
            if name in DIVISORS:
                value = float(getattr(getattr(start, group), key))
                lower, upper = (DIVISOR_MARGIN, upper) if value > 0.0 else (lower, -DIVISOR_MARGIN)
            out.append(Parameter(name, kind_of(name), lower, upper))
    return tuple(out)


def to_vector(preset: RuleParams, names: Sequence[str]) -> FloatArray:
    """The values of ``names`` (``group.key``) in ``preset``."""
    flat = preset.flat()
    return np.array([flat[n] for n in names], dtype=np.float64)


def clamp(values: FloatArray, params: Sequence[Parameter]) -> FloatArray:
    """``values`` held within each parameter's bounds."""
    lower = np.array([p.lower for p in params])
    upper = np.array([p.upper for p in params])
    out: FloatArray = np.minimum(np.maximum(values, lower), upper)
    return out


def ties(start: RuleParams) -> dict[str, str]:
    """The :data:`TIES` in force for ``start``: held key -> fitted key it follows."""
    flat = start.flat()
    return {held: fitted for held, fitted in TIES.items() if flat[held] == flat[fitted]}


def from_vector(start: RuleParams, names: Sequence[str], values: FloatArray) -> RuleParams:
    """``start`` with ``names`` set to ``values`` (and their ties), validated like a loaded preset."""
    changes = {n: float(v) for n, v in zip(names, values, strict=True)}
    for held, fitted in ties(start).items():
        if fitted in changes:
            changes[held] = changes[fitted]
    return start.with_values(changes)
