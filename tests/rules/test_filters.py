"""The smoothing and follow-through over a whole take: compiled from the same step the live tick runs."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.rules.animator import DamperState, SpringState, damper_step, spring_step
from riderlive.rules.filters import damp_rows, damp_series, spring_rows, spring_series


def take(n: int, channels: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Random targets and uneven times, with a repeated time (dt = 0) and a step back (dt < 0)."""
    rng = np.random.default_rng(seed)
    times = np.cumsum(rng.uniform(0.0, 0.02, n))
    if n > 6:
        times[4] = times[3]
        times[6] = times[5] - 0.001
    return rng.normal(size=(n, channels)), times


def stepped_damper(values: np.ndarray, times: np.ndarray, tau: float) -> np.ndarray:
    """The live tick's step, frame by frame (the interpreted reference)."""
    state, out = DamperState(values[0].copy(), np.zeros(values.shape[1])), [values[0].copy()]
    for i in range(1, len(values)):
        state = damper_step(state, values[i], float(times[i] - times[i - 1]), tau)
        out.append(state.value)
    return np.array(out)


def stepped_spring(values: np.ndarray, times: np.ndarray, frequency: float, damping: float) -> np.ndarray:
    state, out = SpringState(values[0].copy(), np.zeros(values.shape[1])), [values[0].copy()]
    for i in range(1, len(values)):
        state = spring_step(state, values[i], float(times[i] - times[i - 1]), frequency, damping)
        out.append(state.value)
    return np.array(out)


@settings(max_examples=25, deadline=None)
@given(st.integers(1, 300), st.integers(1, 6), st.integers(0, 2**32 - 1), st.floats(1e-3, 1.0))
def test_compiled_damper_equals_the_live_step(n: int, channels: int, seed: int, tau: float) -> None:
    values, times = take(n, channels, seed)
    np.testing.assert_allclose(damp_series(values, times, tau), stepped_damper(values, times, tau), rtol=0, atol=1e-12)


@settings(max_examples=25, deadline=None)
@given(st.integers(1, 300), st.integers(1, 6), st.integers(0, 2**32 - 1), st.floats(0.1, 8.0), st.floats(0.05, 0.95))
def test_compiled_spring_equals_the_live_step(n: int, channels: int, seed: int, frequency: float, zeta: float) -> None:
    values, times = take(n, channels, seed)
    expected = stepped_spring(values, times, frequency, zeta)
    np.testing.assert_allclose(spring_series(values, times, frequency, zeta), expected, rtol=0, atol=1e-12)


@pytest.mark.parametrize("cuts", [[1], [7, 8], [50, 51, 199], list(range(0, 300, 13))])
def test_pieces_with_carried_state_equal_the_whole_take(cuts: list[int]) -> None:
    values, times = take(300, 4, 9)
    rows = np.ascontiguousarray(values.T)
    whole_damp, whole_spring = damp_series(values, times, 0.04), spring_series(values, times, 3.0, 0.3)
    damped, sprung = rows.copy(), rows.copy()
    d_state = s_state = None
    for a, b in zip([0, *cuts], [*cuts, 300], strict=True):
        piece = np.ascontiguousarray(damped[:, a:b])
        d_state = damp_rows(piece, times[a:b], 0.04, d_state)
        damped[:, a:b] = piece
        piece = np.ascontiguousarray(sprung[:, a:b])
        s_state = spring_rows(piece, times[a:b], 3.0, 0.3, s_state)
        sprung[:, a:b] = piece
    np.testing.assert_array_equal(damped.T, whole_damp)
    np.testing.assert_array_equal(sprung.T, whole_spring)
    assert d_state is not None and d_state.time == times[-1]


def test_off_passes_through_and_rows_must_be_c_contiguous() -> None:
    values, times = take(20, 3, 1)
    rows = np.ascontiguousarray(values.T)
    state = damp_rows(rows, times, 0.0)
    np.testing.assert_array_equal(rows, values.T)
    assert state is not None and state.value.tolist() == values[-1].tolist() and not state.velocity.any()
    spring_rows(rows, times, 0.0, 0.3)
    np.testing.assert_array_equal(rows, values.T)
    with pytest.raises(ValueError, match="C-contiguous"):
        damp_rows(np.asfortranarray(values.T), times, 0.1)
    with pytest.raises(ValueError, match="20 frames but 19 times"):
        damp_rows(rows, times[:-1], 0.1)


def test_importing_the_rules_does_not_import_numba() -> None:
    """The web process and the CLI load the rules; numba (about a second) only with a whole-take filter."""
    import subprocess
    import sys

    code = "import sys, riderlive.rules, riderlive.rules.animator; print('numba' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
