"""The fit's objective: rider channels predicted from horse takes, against rider takes.

A :class:`TakePair` is a horse take and the rider recorded with it. :func:`align` reads the
horse at each rider frame's time plus a clock offset (linear interpolation; rider frames
outside the horse take, or with a missing value, are left out per channel). The objective
is half the sum of squared weighted residuals over every take and fitted channel::

    r = (predicted - measured) / sigma(kind)

``sigma``: 1 degree for rotations, 1 cm (in the take's length unit) for translations, 1 for
the unitless hair and cloth attributes (:func:`channel_sigma`). With ``drift`` on, each
take's translation channels lose their mean and linear trend (predicted and measured alike:
a projection, so the fit is exact least squares with a free offset and drift per channel),
which a mocap take's drifting translations need; their rest offsets then cannot be
identified. Predictions come from the engine's batch path
(:meth:`riderlive.rules.engine.RiderModel.evaluate_columns`); derivatives from the same rules
on dual numbers (:mod:`riderlive.fit.dual`), accumulated as normal equations channel by
channel (each channel touches a dozen parameters, so ``J^T J`` costs little).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from riderlive.channels import RIDER_INDEX, Kind, lookup
from riderlive.fit.dual import Dual, dual_rules, tangent_of, value_of
from riderlive.frameunits import METRES
from riderlive.rules.engine import RiderModel
from riderlive.rules.kuhnel2003 import RULE_INPUTS
from riderlive.rules.params import RuleParams, Terrain
from riderlive.rules.terrain import LEAN_OUTPUT, PITCH_ARGUMENT, lean

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

HORSE_READ: tuple[str, ...] = (*RULE_INPUTS, "ground.rz")
"""The horse channels the fit reads (the rules' thirteen and the ground's pitch)."""
ROTATION_SIGMA = 1.0  # degrees
TRANSLATION_SIGMA_M = 0.01  # metres
ATTRIBUTE_SIGMA = 1.0
_INPUT_GAIN_IS_SCALE = tuple(lookup(n).kind is Kind.TRANSLATION for n in RULE_INPUTS)
_TERRAIN_KEYS = ("upright", "uphill_lean", "downhill_lean")


class FitInputError(ValueError):
    """Takes the fit cannot use; the message says which and why."""


@dataclass(frozen=True)
class HorseTake:
    """A horse take: ``t`` (N,) seconds, ``columns`` of :data:`HORSE_READ` (absent ``ground.rz``: flat),
    lengths in a unit of ``scale`` thesis rig units."""

    name: str
    t: FloatArray
    columns: Mapping[str, FloatArray]
    scale: float
    sha256: str = ""


@dataclass(frozen=True)
class RiderTake:
    """A rider take: ``t`` (M,) seconds, ``values`` (M, C) of rider channels ``names`` (NaN: missing),
    lengths in the horse take's unit."""

    name: str
    t: FloatArray
    names: tuple[str, ...]
    values: FloatArray
    sha256: str = ""


@dataclass(frozen=True)
class TakePair:
    horse: HorseTake
    rider: RiderTake


@dataclass(frozen=True)
class Aligned:
    """A pair on the rider's frames: the horse read at ``t + offset``; ``valid`` (M, C) per channel."""

    pair: TakePair
    offset: float
    inputs: tuple[FloatArray, ...]  # RULE_INPUTS at the rider's frames, horse units
    ground: FloatArray
    valid: BoolArray
    sigma: FloatArray  # (C,)
    drift: bool
    projections: dict[int, FloatArray] = field(default_factory=dict)  # channel -> (n_valid, 2) orthonormal

    @property
    def channels(self) -> tuple[str, ...]:
        return self.pair.rider.names


def channel_sigma(name: str, scale: float) -> float:
    """The residual unit of rider channel ``name`` for a take in a unit of ``scale`` rig units."""
    kind = lookup(name).kind
    if kind is Kind.ROTATION:
        return ROTATION_SIGMA
    if kind is Kind.TRANSLATION:
        return TRANSLATION_SIGMA_M * METRES / scale
    return ATTRIBUTE_SIGMA


def overlap(pair: TakePair, offset: float) -> tuple[float, float]:
    """The time span (rider clock, s) both takes cover with ``offset`` applied."""
    horse, rider = pair.horse.t, pair.rider.t
    return max(rider[0], horse[0] - offset), min(rider[-1], horse[-1] - offset)


def align(pair: TakePair, offset: float, drift: bool = False) -> Aligned:
    """``pair`` with the horse at rider time + ``offset`` (s); see the module docstring."""
    horse, rider = pair.horse, pair.rider
    at = rider.t + offset
    inside = (at >= horse.t[0]) & (at <= horse.t[-1])
    inputs = tuple(np.interp(at, horse.t, horse.columns[n]) for n in RULE_INPUTS)
    ground_column = horse.columns.get("ground.rz")
    ground = np.interp(at, horse.t, ground_column) if ground_column is not None else np.zeros(len(at))
    finite_horse = np.all(np.isfinite(np.vstack([*inputs, ground])), axis=0)
    valid = np.isfinite(rider.values) & (inside & finite_horse)[:, None]
    sigma = np.array([channel_sigma(n, horse.scale) for n in rider.names])
    projections: dict[int, FloatArray] = {}
    if drift:
        for c, name in enumerate(rider.names):
            if lookup(name).kind is Kind.TRANSLATION and valid[:, c].sum() >= 3:
                t = rider.t[valid[:, c]]
                basis = np.column_stack([np.ones_like(t), t - t.mean()])
                projections[c] = np.linalg.qr(basis)[0]
    return Aligned(pair, offset, inputs, ground, valid, sigma, drift, projections)


def _project(aligned: Aligned, c: int, x: FloatArray) -> FloatArray:
    q = aligned.projections.get(c)
    return x if q is None else x - q @ (q.T @ x)


def predict(aligned: Aligned, preset: RuleParams) -> FloatArray:
    """The rider channels of ``aligned`` predicted by ``preset`` (M, C), the engine's batch path."""
    model = RiderModel(params=preset, scale=aligned.pair.horse.scale)
    columns = dict(zip(RULE_INPUTS, aligned.inputs, strict=True)) | {"ground.rz": aligned.ground}
    full = model.evaluate_columns(columns, len(aligned.pair.rider.t), compiled=False)
    return full[:, [RIDER_INDEX[n] for n in aligned.channels]]


def residuals(aligned: Aligned, preset: RuleParams) -> list[FloatArray]:
    """Per channel, the weighted residuals on the valid frames (projected when ``drift``)."""
    predicted = predict(aligned, preset)
    measured = aligned.pair.rider.values
    out = []
    for c in range(len(aligned.channels)):
        rows = aligned.valid[:, c]
        out.append(_project(aligned, c, (predicted[rows, c] - measured[rows, c]) / aligned.sigma[c]))
    return out


def cost(takes: Sequence[Aligned], preset: RuleParams) -> float:
    """Half the sum of squared weighted residuals over ``takes``."""
    return 0.5 * sum(float(r @ r) for a in takes for r in residuals(a, preset))


@dataclass(frozen=True)
class Linearised:
    """The objective at one point: ``cost``, ``normal`` = J^T J (P, P), ``gradient`` = J^T r (P,), ``rows`` M."""

    cost: float
    normal: FloatArray
    gradient: FloatArray
    rows: int


def linearise(
    takes: Sequence[Aligned], preset: RuleParams, names: Sequence[str], held_ties: Mapping[str, str]
) -> Linearised:
    """Cost, J^T J and J^T r over ``takes`` with respect to ``names`` (every parameter, at ``preset``)."""
    p = len(names)
    normal, gradient, total, rows = np.zeros((p, p)), np.zeros(p), 0.0, 0
    index = {n: k for k, n in enumerate(names)}
    terrain = [index.get(f"terrain.{key}") for key in _TERRAIN_KEYS]
    rules = dual_rules(preset, names, held_ties)
    for aligned in takes:
        scale = aligned.pair.horse.scale
        n = len(aligned.pair.rider.t)
        inputs = [x * scale if is_len else x for x, is_len in zip(aligned.inputs, _INPUT_GAIN_IS_SCALE, strict=True)]
        sloped = bool(aligned.ground.any())
        if sloped:
            inputs[PITCH_ARGUMENT] = inputs[PITCH_ARGUMENT] - aligned.ground
        outputs = list(rules(*inputs))
        if sloped:  # the [terrain] lean: linear in its three numbers, so each column is lean() of a unit preset
            lean_out = outputs[LEAN_OUTPUT] + lean(preset.terrain, aligned.ground)
            tangent = dict(tangent_of(lean_out))
            for key, k in zip(_TERRAIN_KEYS, terrain, strict=True):
                if k is not None:
                    unit = Terrain(**{kk: float(kk == key) for kk in _TERRAIN_KEYS})
                    tangent[k] = lean(unit, aligned.ground)
            outputs[LEAN_OUTPUT] = Dual(value_of(lean_out), tangent)
        for c, name in enumerate(aligned.channels):
            j = RIDER_INDEX[name]
            out_scale = 1.0 / scale if lookup(name).kind is Kind.TRANSLATION else 1.0
            valid = aligned.valid[:, c]
            n_valid = int(valid.sum())
            weight = out_scale / aligned.sigma[c]
            value = np.broadcast_to(value_of(outputs[j]), (n,))[valid] * out_scale
            r = _project(aligned, c, (value - aligned.pair.rider.values[valid, c]) / aligned.sigma[c])
            total += 0.5 * float(r @ r)
            rows += len(r)
            tangent = tangent_of(outputs[j])
            if not tangent:
                continue
            keys = sorted(tangent)
            jac = np.empty((len(keys), n))
            for row, k in enumerate(keys):
                jac[row] = tangent[k]
            jac = jac[:, valid] if n_valid < n else jac
            jac *= weight
            if c in aligned.projections:
                q = aligned.projections[c]
                jac -= (jac @ q) @ q.T
            normal[np.ix_(keys, keys)] += jac @ jac.T
            gradient[keys] += jac @ r
    return Linearised(total, normal, gradient, rows)
