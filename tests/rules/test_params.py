"""Presets: shipped ones load, bad ones fail naming file and key."""

from __future__ import annotations

from pathlib import Path

import pytest

from riderlive.configfile import ConfigError
from riderlive.rules.params import RuleParams, load_preset, shipped_presets


def test_thesis_preset_is_the_default_model() -> None:
    assert load_preset("kuhnel2003").model_dump(exclude={"name", "description"}) == RuleParams().model_dump(
        exclude={"name", "description"}
    )


def test_shipped_presets() -> None:
    assert {"kuhnel2003", "kuhnel2003_literal", "english", "child"} <= set(shipped_presets())
    for name in shipped_presets():
        assert load_preset(name).name == name


def test_literal_preset_differs_only_in_errata_and_keeps_appendix_b_over_a_fence() -> None:
    thesis, literal = load_preset("kuhnel2003").flat(), load_preset("kuhnel2003_literal").flat()
    changed = {k for k in thesis if thesis[k] != literal[k]}
    assert changed - {"jump.weight"} and all(k.startswith("errata.") for k in changed - {"jump.weight"})
    assert (thesis["jump.weight"], literal["jump.weight"]) == (1.0, 0.0)


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("text", "key", "message"),
    [
        ("[head]\nlift_gian = 2.0\n", "head.lift_gian", "unknown key"),
        ("[head]\nlift_gain = nan\n", "head.lift_gain", "finite"),
        ("[lift]\nlimit = inf\n", "lift.limit", "finite"),
        ("[headd]\nx = 1\n", "headd", "unknown key"),
        ("[squash]\nspine_divisor = 0.0\n", "squash.spine_divisor", "zero"),
        ("[seat_shift]\nlimit = -1.0\n", "seat_shift.limit", "greater than or equal"),
        ("[feet]\nheight_limit = 'high'\n", "feet.height_limit", "number"),
    ],
)
def test_bad_preset_names_file_and_key(tmp_path: Path, text: str, key: str, message: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as err:
        load_preset(path)
    assert err.value.source == str(path)
    assert err.value.key == key
    assert message in err.value.message
    assert str(path) in str(err.value) and key in str(err.value)


def test_broken_toml_and_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_preset(write(tmp_path, "[head\n"))
    with pytest.raises(ConfigError, match="file not found"):
        load_preset(tmp_path / "nope.toml")


def test_partial_preset_keeps_thesis_values(tmp_path: Path) -> None:
    params = load_preset(write(tmp_path, "[head]\nlift_gain = 9.0\n"))
    assert params.head.lift_gain == 9.0
    assert params.head.back_gain == 0.9
    assert params.name == "bad"


def test_with_values_validates() -> None:
    params = RuleParams().with_values({"head.lift_gain": 3.0, "waist.gain": 2.0})
    assert (params.head.lift_gain, params.waist.gain) == (3.0, 2.0)
    with pytest.raises(KeyError, match="unknown rule parameter"):
        RuleParams().with_values({"head.nope": 1.0})
    with pytest.raises(ConfigError, match="finite"):
        RuleParams().with_values({"head.lift_gain": float("nan")})
