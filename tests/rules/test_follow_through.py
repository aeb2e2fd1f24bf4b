"""Follow-through (section 9.3, "could be loosened up"): an underdamped spring in the animator layer."""

from __future__ import annotations

import math

import numpy as np
import pytest

from riderlive.channels import HORSE_INDEX, HORSE_NAMES, RIDER_INDEX, RIDER_NAMES
from riderlive.horse import ProceduralHorse
from riderlive.ranges import DEFAULT_RANGES
from riderlive.realtime.core import TickCore, Timing
from riderlive.rules import RiderModel
from riderlive.rules.animator import SpringState, spring_step
from riderlive.rules.filters import spring_series
from riderlive.rules.params import load_preset


def step_response(frequency: float, damping: float, dt: float, seconds: float) -> np.ndarray:
    state = SpringState(np.zeros(1), np.zeros(1))
    out = []
    for _ in range(round(seconds / dt)):
        state = spring_step(state, np.ones(1), dt, frequency, damping)
        out.append(state.value[0])
    return np.array(out)


@pytest.mark.parametrize(("frequency", "damping"), [(2.0, 0.2), (1.5, 0.4), (4.0, 0.7)])
def test_step_overshoot_and_period_are_the_documented_ones(frequency: float, damping: float) -> None:
    dt = 1e-4
    x = step_response(frequency, damping, dt, 3.0)
    overshoot = math.exp(-math.pi * damping / math.sqrt(1.0 - damping * damping))
    assert x.max() - 1.0 == pytest.approx(overshoot, rel=1e-3)
    peak = (int(np.argmax(x)) + 1) * dt  # the first peak is half a damped period after the step
    assert peak == pytest.approx(math.pi / (2 * math.pi * frequency * math.sqrt(1 - damping * damping)), rel=1e-3)


def test_how_time_is_cut_does_not_matter() -> None:
    """Exact for a target held over each step: 120 Hz and 1 kHz agree at the shared instants."""
    rng = np.random.default_rng(2)
    targets = rng.normal(size=(24, 3))  # one target per 1/12 s
    coarse, fine = SpringState(np.zeros(3), np.zeros(3)), SpringState(np.zeros(3), np.zeros(3))
    for target in targets:
        for _ in range(10):
            coarse = spring_step(coarse, target, 1 / 120, 2.5, 0.3)
        for _ in range(250):
            fine = spring_step(fine, target, 1 / 3000, 2.5, 0.3)
        np.testing.assert_allclose(coarse.value, fine.value, atol=1e-9)
        np.testing.assert_allclose(coarse.velocity, fine.velocity, atol=1e-7)
    times = np.arange(len(targets) * 10) / 120.0
    series = spring_series(np.repeat(targets, 10, axis=0), times, 2.5, 0.3)
    assert np.all(np.isfinite(series))


def test_off_in_the_thesis_presets() -> None:
    for name in ("kuhnel2003", "kuhnel2003_literal"):
        assert load_preset(name).follow_through.frequency == 0.0
    state = spring_step(SpringState(np.zeros(2), np.ones(2)), np.full(2, 3.0), 0.01, 0.0, 0.4)
    assert state.value.tolist() == [3.0, 3.0] and state.velocity.tolist() == [0.0, 0.0]


def loose_core() -> TickCore:
    params = load_preset("kuhnel2003").with_values(
        {"follow_through.frequency": 3.0, "follow_through.damping_ratio": 0.3}
    )
    model = RiderModel(params, scale=25.0)
    low, high = DEFAULT_RANGES.limits(RIDER_NAMES, 25.0)
    return TickCore(model, Timing(delay=0.0, hold=10.0, blend_time=0.0), ProceduralHorse(), bounds=(low, high))


def test_the_tick_overshoots_a_sudden_lean_and_settles() -> None:
    core = loose_core()
    rest = [0.0] * len(HORSE_NAMES)
    pitched = list(rest)
    pitched[HORSE_INDEX["rearPivot.rz"]] = 10.0
    core.push_input(1, 0.0, 0.0, rest)
    core.step(0.0)
    core.push_input(1, 0.001, 0.001, pitched)
    lean = [core.step(t).rider[RIDER_INDEX["lower_back.rz"]] for t in np.arange(0.01, 3.0, 1 / 120)]
    target = core.model.evaluate(pitched)[RIDER_INDEX["lower_back.rz"]]
    start = core.model.evaluate(rest)[RIDER_INDEX["lower_back.rz"]]
    assert (max(lean) - target) / (target - start) == pytest.approx(
        math.exp(-math.pi * 0.3 / math.sqrt(0.91)), rel=0.05
    )
    assert lean[-1] == pytest.approx(target, abs=1e-3 * abs(target - start))


def test_hostile_input_keeps_the_spring_finite_and_bounded() -> None:
    core = loose_core()
    low, high = DEFAULT_RANGES.limits(HORSE_NAMES, 25.0)
    rng = np.random.default_rng(0)
    t = 0.0
    for i in range(300):
        frame = [lo if rng.random() < 0.5 else hi for lo, hi in zip(low, high, strict=True)]
        core.push_input(1, t, t, frame)
        t += 1 / 120 if i % 50 else 1e4  # and a clock that leaps
        out = core.step(t)
        assert all(math.isfinite(v) for v in (*out.rider, *out.parts))
        assert all(lo <= v <= hi for v, lo, hi in zip(out.rider, core.low, core.high, strict=True))
