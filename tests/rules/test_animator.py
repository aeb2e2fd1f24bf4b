"""The animator layer: gain and offset per channel, and the critically damped filter."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.channels import HORSE, RIDER_INDEX
from riderlive.configfile import ConfigError
from riderlive.rules.animator import AnimatorLayer, damper_start, damper_step
from riderlive.rules.engine import RiderModel
from riderlive.rules.filters import damp_series


def test_gain_then_offset_in_output_units() -> None:
    frame = [0.5] * len(HORSE)
    plain = RiderModel().evaluate(frame)
    layer = AnimatorLayer(offsets={"head.rz": 2.0, "cog.ty": 0.5}, gains={"head.rz": 0.5, "cog.ty": 3.0})
    keyed = RiderModel(animator=layer, scale=2.0).evaluate(frame)
    scaled = RiderModel(scale=2.0).evaluate(frame)
    i, j = RIDER_INDEX["head.rz"], RIDER_INDEX["cog.ty"]
    assert keyed[i] == pytest.approx(scaled[i] * 0.5 + 2.0)
    assert keyed[j] == pytest.approx(scaled[j] * 3.0 + 0.5)
    assert keyed[RIDER_INDEX["waist.rz"]] == pytest.approx(scaled[RIDER_INDEX["waist.rz"]])
    assert plain != scaled  # the scale does reach the rotations through the hoof distances


def test_animator_rejects_unknown_channels_and_nan(tmp_path: Path) -> None:
    with pytest.raises(KeyError):
        AnimatorLayer(offsets={"head.rq": 1.0})
    with pytest.raises(ValueError, match="finite"):
        AnimatorLayer(gains={"head.rz": math.inf})
    path = tmp_path / "keys.toml"
    path.write_text('[offsets]\n"head.rq" = 1.0\n')
    with pytest.raises(ConfigError) as err:
        AnimatorLayer.load(path)
    assert err.value.key == "offsets.head.rq"
    path.write_text('[offsets]\n"head.rz" = 1.0\n[gains]\n"cog.ty" = 2.0\n')
    layer = AnimatorLayer.load(path)
    assert layer.offsets == {"head.rz": 1.0} and layer.gains == {"cog.ty": 2.0}


def test_damper_step_response_is_critically_damped() -> None:
    """From rest at 0 toward 1: no overshoot, monotone, 1 - (1 + t/tau) e^(-t/tau)."""
    tau, dt = 0.05, 1.0 / 120.0
    state = damper_start(np.zeros(1))
    values = []
    for k in range(1, 200):
        state = damper_step(state, np.ones(1), dt, tau)
        values.append(state.value[0])
        t = k * dt
        assert state.value[0] == pytest.approx(1.0 - (1.0 + t / tau) * math.exp(-t / tau), abs=1e-12)
    assert all(b >= a for a, b in zip(values, values[1:], strict=False))
    assert max(values) <= 1.0


@settings(max_examples=200, deadline=None)
@given(
    st.floats(-10, 10),
    st.floats(-10, 10),
    st.floats(-10, 10),
    st.floats(1e-3, 1.0),
    st.floats(1e-4, 0.1),
    st.integers(1, 8),
)
def test_damper_does_not_depend_on_how_time_is_cut(
    x0: float, v0: float, target: float, tau: float, dt: float, parts: int
) -> None:
    """With the target held, one step of n*dt equals n steps of dt (exact solution)."""
    from riderlive.rules.animator import DamperState

    start = DamperState(np.array([x0]), np.array([v0]))
    whole = damper_step(start, np.array([target]), dt * parts, tau)
    cut = start
    for _ in range(parts):
        cut = damper_step(cut, np.array([target]), dt, tau)
    assert cut.value[0] == pytest.approx(whole.value[0], abs=1e-9)
    assert cut.velocity[0] == pytest.approx(whole.velocity[0], abs=1e-7)


def test_damp_series_off_passes_through_and_on_lags() -> None:
    times = np.arange(100) / 100.0
    values = np.column_stack([np.where(times >= 0.2, 1.0, 0.0), np.sin(times)])
    np.testing.assert_array_equal(damp_series(values, times, 0.0), values)
    smoothed = damp_series(values, times, 0.05)
    assert smoothed[20, 0] < 0.5 and smoothed[-1, 0] > 0.99
