"""The rules on dual numbers: the same values as the engine, derivatives equal to central differences."""

from __future__ import annotations

import numpy as np
import pytest

from riderlive.channels import RIDER_INDEX, RIDER_NAMES
from riderlive.fit.dual import Dual, dual_rules, tangent_of, value_of
from riderlive.fit.problem import align, linearise, residuals
from riderlive.fit.vector import from_vector, parameters, ties, to_vector
from riderlive.rules.engine import RiderModel
from riderlive.rules.kuhnel2003 import RULE_INPUTS
from riderlive.rules.params import load_preset
from tests.fit.takes import horse_take, pair


@pytest.mark.parametrize("preset_name", ["english", "kuhnel2003_literal"])
@pytest.mark.parametrize("take", ["trot", "jump"])
def test_values_are_the_engines_and_derivatives_match_central_differences(preset_name: str, take: str) -> None:
    preset = load_preset(preset_name)
    horse = horse_take(take, 4.0)
    n = len(horse.t)
    inputs = [horse.columns[name] * (horse.scale if name.endswith(("tx", "ty")) else 1.0) for name in RULE_INPUTS]
    params = parameters(preset)
    names = [p.name for p in params]
    outputs = dual_rules(preset, names, ties(preset))(*inputs)
    engine = RiderModel(params=preset).evaluate_columns(dict(zip(RULE_INPUTS, inputs, strict=True)), n, compiled=False)
    for j, name in enumerate(RIDER_NAMES):
        value = np.broadcast_to(value_of(outputs[j]), (n,))  # the same arithmetic, operands maybe swapped
        np.testing.assert_allclose(value, engine[:, j], rtol=1e-13, atol=1e-13, err_msg=name)
    x = to_vector(preset, names)
    for k, p in enumerate(params):
        if p.name.startswith("terrain."):
            continue  # the lean is added after the rules (tested through linearise below)
        h = 1e-6 * max(abs(x[k]), 1.0)
        up, down = x.copy(), x.copy()
        up[k] += h
        down[k] -= h
        a = RiderModel(params=from_vector(preset, names, up)).evaluate_columns(
            dict(zip(RULE_INPUTS, inputs, strict=True)), n, compiled=False
        )
        b = RiderModel(params=from_vector(preset, names, down)).evaluate_columns(
            dict(zip(RULE_INPUTS, inputs, strict=True)), n, compiled=False
        )
        numeric = (a - b) / (2 * h)
        for j, name in enumerate(RIDER_NAMES):
            exact = np.broadcast_to(tangent_of(outputs[j]).get(k, 0.0), (n,))
            # frames where a clamp or branch switches inside +-h differ; elsewhere the two agree
            close = np.abs(exact - numeric[:, j]) <= 1e-5 * (1.0 + np.abs(exact))
            assert close.mean() >= 0.995, (p.name, name, float(np.max(np.abs(exact - numeric[:, j]))))


def test_normal_equations_equal_the_dense_jacobians() -> None:
    """J^T J and J^T r from the dual equal those of a dense finite-difference Jacobian of residuals()."""
    truth, preset = load_preset("english"), load_preset("child")
    take = align(pair("canter", truth, seconds=3.0), 0.0, drift=True)
    names = [p.name for p in parameters(preset)][:20]
    lin = linearise([take], preset, names, ties(preset))
    x = to_vector(preset, names)

    def flat(values: np.ndarray) -> np.ndarray:
        return np.concatenate(residuals(take, from_vector(preset, names, values)))

    r = flat(x)
    jac = np.empty((len(r), len(names)))
    for k in range(len(names)):
        h = 1e-6 * max(abs(x[k]), 1.0)
        up, down = x.copy(), x.copy()
        up[k] += h
        down[k] -= h
        jac[:, k] = (flat(up) - flat(down)) / (2 * h)
    assert lin.cost == pytest.approx(0.5 * r @ r, rel=1e-12)
    scale = np.sqrt(np.outer(np.diag(jac.T @ jac), np.diag(jac.T @ jac))) + 1e-30
    np.testing.assert_allclose(lin.normal / scale, (jac.T @ jac) / scale, atol=1e-6)
    np.testing.assert_allclose(lin.gradient, jac.T @ r, rtol=1e-5, atol=1e-6 * np.abs(jac.T @ r).max())


def test_a_dual_compares_by_value_and_numpy_defers_to_it() -> None:
    d = Dual(2.0, {0: 1.0})
    product = np.array([1.0, 3.0]) * d
    assert isinstance(product, Dual)
    np.testing.assert_array_equal(product.value, [2.0, 6.0])
    np.testing.assert_array_equal(product.tangent[0], [1.0, 3.0])
    np.testing.assert_array_equal(np.array([1.0, 3.0]) >= d, [False, True])
    assert d == 2.0 and d != 3.0
    quotient = 1.0 / d
    assert quotient.value == 0.5 and quotient.tangent[0] == -0.25
    assert RIDER_INDEX["lower_back.rz"] == 0
