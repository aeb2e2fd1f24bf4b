"""Forward-mode derivatives of the rules with respect to the preset's numbers, from the one source.

:func:`riderlive.rules.kuhnel2003.make_rules` binds a preset's numbers and takes its four
primitives as :class:`~riderlive.rules.kuhnel2003.Ops`. Here the fitted numbers are
:class:`Dual` values (a value and a sparse tangent: parameter index -> derivative, each a
float or an array over frames) and :data:`DUAL_OPS` the primitives on them, so one call of
the very rules the engine runs returns every output channel's value *and* its derivative
with respect to every fitted parameter that reaches it. The rules are mostly linear in
their weights and offsets and piecewise in their clamps: a tangent is carried only where a
parameter enters (a channel depends on a dozen parameters, not all ~90), and a clamp's
derivative is 1 on the frames where it holds and 0 elsewhere (the branch taken, as the
rules take it). One evaluation costs about what a dozen evaluations of the plain rules do,
against one per parameter for finite differences, and the derivatives are exact.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from riderlive.rules.kuhnel2003 import Ops, make_rules
from riderlive.rules.params import RuleParams

Tangent = dict[int, Any]
"""Parameter index -> derivative (a float, or an array over frames)."""


class Dual:
    """``value + sum_k tangent[k] * d p_k``: a float or an array over frames, and its derivatives.

    Comparisons compare values (the rules' branch tests); NumPy defers to this class
    (``__array_ufunc__ = None``), so ``array * dual`` is a :class:`Dual` too.
    """

    __slots__ = ("tangent", "value")
    __array_ufunc__ = None

    def __init__(self, value: Any, tangent: Tangent) -> None:
        self.value = value
        self.tangent = tangent

    def __add__(self, other: Any) -> Dual:
        if isinstance(other, Dual):
            return Dual(self.value + other.value, _combine(self.tangent, other.tangent, 1.0))
        return Dual(self.value + other, self.tangent)

    __radd__ = __add__

    def __sub__(self, other: Any) -> Dual:
        if isinstance(other, Dual):
            return Dual(self.value - other.value, _combine(self.tangent, other.tangent, -1.0))
        return Dual(self.value - other, self.tangent)

    def __rsub__(self, other: Any) -> Dual:
        return Dual(other - self.value, {k: -t for k, t in self.tangent.items()})

    def __neg__(self) -> Dual:
        return Dual(-self.value, {k: -t for k, t in self.tangent.items()})

    def __mul__(self, other: Any) -> Dual:
        if isinstance(other, Dual):
            out = {k: t * other.value for k, t in self.tangent.items()}
            for k, t in other.tangent.items():
                out[k] = out[k] + t * self.value if k in out else t * self.value
            return Dual(self.value * other.value, out)
        return Dual(self.value * other, {k: t * other for k, t in self.tangent.items()})

    __rmul__ = __mul__

    def __truediv__(self, other: Any) -> Dual:
        if isinstance(other, Dual):
            return self * other._reciprocal()
        return self.__mul__(1.0 / other)

    def __rtruediv__(self, other: Any) -> Dual:
        return self._reciprocal().__mul__(other)

    def _reciprocal(self) -> Dual:
        inverse = 1.0 / self.value
        square = -inverse * inverse
        return Dual(inverse, {k: t * square for k, t in self.tangent.items()})

    def __lt__(self, other: Any) -> Any:
        return self.value < value_of(other)

    def __le__(self, other: Any) -> Any:
        return self.value <= value_of(other)

    def __gt__(self, other: Any) -> Any:
        return self.value > value_of(other)

    def __ge__(self, other: Any) -> Any:
        return self.value >= value_of(other)

    def __eq__(self, other: object) -> Any:  # type: ignore[override]
        return self.value == value_of(other)

    def __ne__(self, other: object) -> Any:  # type: ignore[override]
        return self.value != value_of(other)

    __hash__ = None  # type: ignore[assignment]


def value_of(x: Any) -> Any:
    """The value of a :class:`Dual`, or ``x`` itself."""
    return x.value if isinstance(x, Dual) else x


def tangent_of(x: Any) -> Tangent:
    """The tangent of a :class:`Dual`; a constant has none."""
    return x.tangent if isinstance(x, Dual) else {}


def _combine(a: Tangent, b: Tangent, sign: float) -> Tangent:
    out = dict(a)
    for k, t in b.items():
        out[k] = out[k] + sign * t if k in out else sign * t
    return out


def _select(mask: Any, a: Any, b: Any) -> Any:
    """Where ``mask``, ``a``, else ``b`` (values and tangents)."""
    value = np.where(mask, value_of(a), value_of(b))
    ta, tb = tangent_of(a), tangent_of(b)
    if not ta and not tb:
        return value
    tangent = {k: np.where(mask, ta.get(k, 0.0), tb.get(k, 0.0)) for k in ta.keys() | tb.keys()}
    return Dual(value, tangent)


def _abs(x: Any) -> Any:
    if isinstance(x, Dual):
        return _select(x.value >= 0.0, x, -x)
    return np.abs(x)


def _minimum(a: Any, b: Any) -> Any:
    return _select(value_of(a) <= value_of(b), a, b)


def _maximum(a: Any, b: Any) -> Any:
    return _select(value_of(a) >= value_of(b), a, b)


DUAL_OPS = Ops(abs=_abs, minimum=_minimum, maximum=_maximum, where=_select)
"""The rules' primitives on :class:`Dual` values (and plain arrays)."""


def dual_params(preset: RuleParams, names: Sequence[str], held_ties: Mapping[str, str] = {}) -> RuleParams:
    """``preset`` with parameter ``names[k]`` replaced by ``Dual(value, {k: 1})``, unvalidated (for
    :func:`make_rules` only). ``held_ties``: held key -> fitted key whose :class:`Dual` it shares."""
    index = {n: k for k, n in enumerate(names)}
    data = preset.model_dump()
    for name, k in index.items():
        group, key = name.split(".", 1)
        data[group][key] = Dual(float(data[group][key]), {k: 1.0})
    for held, fitted in held_ties.items():
        if fitted in index:
            group, key = held.split(".", 1)
            fgroup, fkey = fitted.split(".", 1)
            data[group][key] = data[fgroup][fkey]
    tables = {
        group: type(getattr(preset, group)).model_construct(**table)
        for group, table in data.items()
        if isinstance(table, dict)
    }
    return RuleParams.model_construct(name=preset.name, description=preset.description, **tables)


def dual_rules(preset: RuleParams, names: Sequence[str], held_ties: Mapping[str, str] = {}) -> Callable[..., Any]:
    """The rules of ``preset`` with derivatives with respect to ``names`` (see the module docstring)."""
    return make_rules(dual_params(preset, names, held_ties), DUAL_OPS)
