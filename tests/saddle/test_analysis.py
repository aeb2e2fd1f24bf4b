"""The analysis' pieces against signals whose answer is known by construction."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.horse import GAIT_TABLE, Gait
from riderlive.horse.curves import ARRAY
from riderlive.horse.model import to_rig_sides
from riderlive.saddle.analysis import analyse, beat_frequency, match, stride_fit
from riderlive.saddle.pose import ARRAY as POSE_ARRAY
from riderlive.saddle.pose import SaddlePoint, saddle_from_trunk
from riderlive.saddle.templates import templates

TEMPLATES = templates(SaddlePoint())


def test_templates_beat_as_the_gaits_do_and_invert_the_frequency_law() -> None:
    assert {g.value: t.beats for g, t in TEMPLATES.items()} == {"walk": 2, "trot": 2, "canter": 1, "gallop": 1}
    for gait, template in TEMPLATES.items():
        spec = GAIT_TABLE[gait]
        for speed in np.linspace(*spec.speed, 5):
            assert template.speed_at(spec.frequency_at(speed)) == pytest.approx(speed)
        assert template.speed_at(0.0) == spec.speed[0] and template.speed_at(99.0) == spec.speed[1]


@pytest.mark.parametrize("gait", list(Gait)[:4])
def test_two_harmonics_rebuild_the_horses_saddle(gait: Gait) -> None:
    template = TEMPLATES[gait]
    phases = np.linspace(0.0, 1.0, 97)
    body = to_rig_sides(template.layer.pose_at(phases, template.spec.default_speed, ARRAY))
    trunk = [np.broadcast_to(np.asarray(v, dtype=float), phases.shape) for v in body[12:18]]
    saddle = np.column_stack(saddle_from_trunk(trunk, np.asarray(body[18]), SaddlePoint(), POSE_ARRAY))
    waves = np.exp(2j * np.pi * np.outer(phases, [1, 2]))  # (N, 2)
    rebuilt = (waves[:, None, :] * template.harmonics[None, :, :]).real.sum(axis=2)
    wobble = saddle - saddle.mean(axis=0)
    assert np.max(np.abs(rebuilt - wobble) / (np.ptp(saddle, axis=0) + 1e-9)) < 0.03  # k >= 3 is 3 % at most


@given(
    st.floats(1.3, 3.3),
    st.floats(0.0, 2.0 * math.pi),
    st.floats(-0.1, 0.1),
    st.floats(-0.05, 0.05),
    st.integers(0, 2**31),
)
@settings(max_examples=40, deadline=None)
def test_beat_frequency_finds_a_sinusoid_on_a_drift(
    hz: float, phase: float, slope: float, level: float, seed: int
) -> None:
    rng = np.random.default_rng(seed)
    tau = np.sort(rng.uniform(-1.2, 0.0, 120))
    y = 1.0 * np.cos(2 * math.pi * hz * tau + phase) + level + slope * tau + rng.normal(scale=0.1, size=tau.shape)
    found, explained = beat_frequency(tau, y[:, None], np.ones((len(tau), 1), bool))
    cycles = 1.2 * hz  # in the window; with fewer than two, noise moves the estimate more
    assert found == pytest.approx(hz, rel=0.015 if cycles >= 2.0 else 0.03)
    assert explained > 0.9


def test_stride_fit_recovers_harmonics_under_a_drift_line_and_a_missing_axis() -> None:
    tau = np.linspace(-0.8, 0.0, 97)
    truth = np.array([[0.01 + 0.02j, 0.005j], [0.0, 0.03], [0.02, 0.0], [1.0 - 1.0j, 0.2], [0.5j, 0.0], [0.0, 3.0]])
    waves = np.exp(2j * np.pi * 1.3 * np.outer(tau, [1, 2]))
    y = (waves[:, None, :] * truth[None]).real.sum(axis=2) + 0.3 + 0.02 * tau[:, None]
    mask = np.ones_like(y, bool)
    mask[::3, 4] = False
    y[~mask] = np.nan
    fit = stride_fit(tau, y, mask, 1.3)
    np.testing.assert_allclose(fit.harmonics, truth, atol=1e-9)
    np.testing.assert_allclose(fit.level, 0.3, atol=1e-9)
    np.testing.assert_allclose(fit.slope, 0.02, atol=1e-8)


@given(st.sampled_from(list(Gait)[:4]), st.floats(0.0, 1.0, exclude_max=True), st.floats(0.3, 3.0))
@settings(max_examples=60, deadline=None)
def test_match_finds_the_phase_a_template_was_turned_by(gait: Gait, phase: float, size: float) -> None:
    template = TEMPLATES[gait]
    turned = template.harmonics * size * np.exp(2j * np.pi * np.array([1, 2]) * phase)
    found = match(turned, template, template.spec.frequency_at(template.spec.default_speed))
    turn = 0.5 if found.half else 1.0
    assert abs((found.phase - phase + turn / 2) % turn - turn / 2) < 1e-3
    assert found.score == pytest.approx(1.0, abs=1e-9)
    assert found.size == pytest.approx(size)
    assert not found.half


def test_analyse_names_gait_and_phase_from_one_stride_of_history() -> None:
    from riderlive.horse import ProceduralHorse
    from riderlive.horse.curves import SCALAR
    from riderlive.horse.layers import GaitLayer
    from riderlive.saddle.pose import saddle_matrix

    for gait in ("walk", "trot", "canter", "gallop"):
        horse = ProceduralHorse(gait)
        f = GAIT_TABLE[Gait(gait)].frequency_at(horse.speed)
        times = 0.37 + np.arange(0.0, 1.4 / f, 1 / 200)
        saddle = saddle_matrix(np.array([horse.sample(t) for t in times]))
        fit = analyse(times, saddle, TEMPLATES)
        assert fit is not None and fit.gait is Gait(gait)
        layer = horse.state.layer if horse.state else None
        assert isinstance(layer, GaitLayer)
        true_phase = layer.phase(times[-1], SCALAR)[0]
        assert abs((fit.phase - true_phase + 0.5) % 1.0 - 0.5) < 0.005
        assert fit.stride == pytest.approx(f, rel=0.005)
