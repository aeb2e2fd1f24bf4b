"""Thesis section 10, sloping ground: the rules read the horse relative to the ground, the rider leans."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.channels import HORSE, HORSE_GROUND, HORSE_INDEX, RIDER, RIDER_INDEX, Kind
from riderlive.configfile import ConfigError
from riderlive.horse import DEFAULT_SCALE, ProceduralHorse, ShotScript, TerrainConfig, generate
from riderlive.realtime.core import Mode, TickCore, Timing
from riderlive.rules.animator import AnimatorLayer
from riderlive.rules.engine import RiderModel
from riderlive.rules.kuhnel2003 import RULE_INPUTS, SCALAR_OPS, make_rules
from riderlive.rules.params import RuleParams, load_preset
from riderlive.rules.terrain import GROUND_RELATIVE, ground_relative, ground_relative_columns, lean

GROUND = HORSE_INDEX["ground.rz"]
LOWER_BACK = RIDER_INDEX["lower_back.rz"]
WORLD = {"root.tx", "root.ty", "ground.rz", "ground.ty"}
"""Channels that carry the ground or the world placement: the ground-relative frame keeps them."""
finite = st.floats(min_value=-60.0, max_value=60.0, allow_nan=False)


def take(terrain: dict[str, object] | None, gait: str = "trot", seconds: float = 6.0) -> np.ndarray:
    script = ShotScript.model_validate({"terrain": terrain, "seed": 4, "segment": [{"gait": gait, "seconds": seconds}]})
    return generate(script, 120.0).values


@settings(max_examples=300, deadline=None)
@given(st.lists(finite, min_size=len(HORSE), max_size=len(HORSE)), st.booleans())
def test_flat_ground_is_appendix_b_exactly(frame: list[float], old_length: bool) -> None:
    """ground.rz 0 (or a frame from before the ground channels): the rules of today, to 1e-12."""
    frame[GROUND] = 0.0
    if old_length:
        frame = frame[: -len(HORSE_GROUND)]
    model = RiderModel(RuleParams().with_values({"jump.weight": 0.0}), scale=2.0)  # Appendix B alone
    rules = make_rules(RuleParams(), SCALAR_OPS)
    length = {c.name for c in HORSE if c.kind is Kind.TRANSLATION}
    today = rules(*(frame[HORSE_INDEX[n]] * (2.0 if n in length else 1.0) for n in RULE_INPUTS))
    expected = [v / 2.0 if c.kind is Kind.TRANSLATION else v for v, c in zip(today, RIDER, strict=True)]
    np.testing.assert_allclose(model.evaluate(frame), expected, rtol=0.0, atol=1e-12)
    if not old_length:
        np.testing.assert_allclose(model.evaluate_batch(np.array([frame]))[0], expected, rtol=0.0, atol=1e-12)


def test_ground_relative_takes_the_ground_out_of_the_pitch_only() -> None:
    rng = np.random.default_rng(1)
    frame = rng.normal(scale=5.0, size=len(HORSE)).tolist()
    out = ground_relative(frame)
    assert GROUND_RELATIVE == ("rearPivot.rz",)
    for name, i in HORSE_INDEX.items():
        expected = frame[i] - frame[GROUND] if name == "rearPivot.rz" else frame[i]
        assert out[i] == expected, name
    np.testing.assert_array_equal(ground_relative_columns(np.array([frame]))[0], out)


@pytest.mark.parametrize(("slope", "gain"), [(8.0, 1.0 + 0.5), (-6.0, 1.0 + 0.1)])
def test_on_a_constant_slope_the_rules_see_the_flat_horse_and_the_rider_leans(slope: float, gain: float) -> None:
    flat, sloped = take(None), take({"slope": slope})
    relative = ground_relative_columns(sloped)
    for name, i in HORSE_INDEX.items():
        if name not in WORLD:
            np.testing.assert_allclose(relative[:, i], flat[:, i], rtol=0.0, atol=1e-9, err_msg=name)
    np.testing.assert_allclose(sloped[:, GROUND], slope, atol=1e-9)
    model = RiderModel(scale=DEFAULT_SCALE)
    on_flat, on_slope = model.evaluate_batch(flat), model.evaluate_batch(sloped)
    assert lean(model.params.terrain, slope) == pytest.approx(gain * slope)
    np.testing.assert_allclose(on_slope[:, LOWER_BACK] - on_flat[:, LOWER_BACK], gain * slope, atol=1e-9)
    others = [i for i in range(on_flat.shape[1]) if i != LOWER_BACK]
    np.testing.assert_allclose(on_slope[:, others], on_flat[:, others], rtol=0.0, atol=1e-9)
    # The rider's trunk in the world: the horse's pitch plus her lower back; on the slope it is the
    # flat ground's plus the preset's lean beyond upright (uphill_lean or downhill_lean times the slope).
    world_flat = flat[:, HORSE_INDEX["rearPivot.rz"]] * -1.0 + on_flat[:, LOWER_BACK]
    world_slope = sloped[:, HORSE_INDEX["rearPivot.rz"]] * -1.0 + on_slope[:, LOWER_BACK]
    np.testing.assert_allclose(world_slope - world_flat, (gain - 1.0) * slope, atol=1e-9)


def _sloped_frames(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    horse = rng.normal(scale=6.0, size=(n, len(HORSE)))
    for hoof in ("lfHoof", "rfHoof", "lbHoof", "rbHoof"):
        horse[:, HORSE_INDEX[f"{hoof}.ty"]] = rng.uniform(0.0, 14.0, n)
    horse[:, GROUND] = rng.uniform(-30.0, 30.0, n)
    horse[::5, GROUND] = 0.0  # flat frames mixed in
    return horse


@pytest.mark.parametrize("compiled", [False, True])
def test_scalar_batch_and_columns_agree_on_slopes(compiled: bool) -> None:
    animator = AnimatorLayer(offsets={"lower_back.rz": 1.5}, gains={"lower_back.rz": 1.3})
    model = RiderModel(params=load_preset("kuhnel2003"), scale=2.5, animator=animator)
    horse = _sloped_frames(3000, seed=9)
    scalar = np.array([model.evaluate(row) for row in horse.tolist()])
    np.testing.assert_allclose(model.evaluate_batch(horse, compiled=compiled), scalar, rtol=0.0, atol=1e-12)
    columns = {name: horse[:, i] for name, i in HORSE_INDEX.items()}
    np.testing.assert_allclose(
        model.evaluate_columns(columns, len(horse), compiled=compiled), scalar, rtol=0.0, atol=1e-12
    )


def test_the_tick_core_leans_the_rider_on_the_procedural_hill() -> None:
    terrain = TerrainConfig(slope=10.0).terrain()
    model = RiderModel(scale=DEFAULT_SCALE)
    core = TickCore(model, Timing(), ProceduralHorse("walk", terrain=terrain), Mode.PROCEDURAL)
    flat = TickCore(model, Timing(), ProceduralHorse("walk"), Mode.PROCEDURAL)
    for now in np.arange(0.0, 2.0, 0.01):
        a, b = core.step(float(now)), flat.step(float(now))
    assert a.horse[GROUND] == pytest.approx(10.0)
    assert a.rider[LOWER_BACK] - b.rider[LOWER_BACK] == pytest.approx(15.0, abs=1e-9)


@pytest.mark.parametrize(
    ("text", "key", "message"),
    [
        ("[terrain]\nupright = 1.5", "terrain.upright", "less than or equal to 1"),
        ("[terrain]\nuphill_lean = -0.1", "terrain.uphill_lean", "greater than or equal to 0"),
        ("[terrain]\ndownhill_lean = 2", "terrain.downhill_lean", "less than or equal to 1"),
        ("[terrain]\nlean = 2", "terrain.lean", "unknown key"),
    ],
)
def test_bad_terrain_presets_name_file_key_and_range(tmp_path: Path, text: str, key: str, message: str) -> None:
    path = tmp_path / "hilly.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message) as err:
        load_preset(path)
    assert str(err.value).startswith(f"{path}: {key}:")
