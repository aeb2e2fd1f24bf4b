"""Platform files: the shipped ones load, bad ones fail naming the file and the key."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest

from riderlive.configfile import ConfigError, read_toml
from riderlive.platform.mechanism.config import (
    PLATFORM_DIR,
    build_geometry,
    load_platform,
    platform_from_dict,
    platform_problems,
    shipped_platforms,
)
from riderlive.platform.mechanism.cueing_params import PRESETS
from riderlive.platform.mechanism.geometry import Kind


def data(name: str) -> dict[str, Any]:
    return copy.deepcopy(read_toml(PLATFORM_DIR / f"{name}.toml"))


def error_for(d: dict[str, Any]) -> ConfigError:
    with pytest.raises(ConfigError) as info:
        platform_from_dict(d, "my_platform.toml")
    assert str(info.value).startswith("my_platform.toml: ")
    return info.value


def test_the_shipped_platforms_load() -> None:
    assert shipped_platforms() == ["heave_pitch_roll", "stewart_compact", "stewart_linear", "stewart_rotary"]
    kinds = {load_platform(name).kind for name in shipped_platforms()}
    assert kinds == set(Kind)
    cfg = load_platform(PLATFORM_DIR / "stewart_rotary.toml")
    assert cfg.carries == "puppet" and cfg.actuators.arm_length == 0.06
    assert load_platform("stewart_linear").cueing == PRESETS["standard"]


def test_unknown_keys_are_errors() -> None:
    d = data("stewart_linear")
    d["actuators"]["stroke"] = 0.25
    err = error_for(d)
    assert (err.key, err.message) == ("actuators.stroke", "unknown key")
    d = data("stewart_linear")
    d["cueing"]["washout_hz"] = 0.5
    assert error_for(d).key == "cueing.washout_hz"


def test_limits_in_the_wrong_order() -> None:
    d = data("stewart_linear")
    d["actuators"]["max_length"] = 0.55
    err = error_for(d)
    assert err.key == "actuators.max_length" and "above min_length" in err.message
    d = data("stewart_rotary")
    d["actuators"]["min_angle_deg"], d["actuators"]["max_angle_deg"] = 40.0, -40.0
    assert error_for(d).key == "actuators.max_angle_deg"
    d = data("stewart_rotary")
    d["actuators"]["rod_length"] = 0.05
    assert error_for(d).key == "actuators.rod_length"
    d = data("stewart_linear")
    d["actuators"]["soft_margin"] = 0.2
    assert error_for(d).key == "actuators.soft_margin"


def test_a_home_the_platform_cannot_reach() -> None:
    d = data("stewart_linear")
    d["home"]["ty"] = 0.75  # legs would need ~0.91 m: beyond the 0.85 m extension
    err = error_for(d)
    assert err.key == "home"
    assert "actuator 1 needs" in err.message and "above its soft range" in err.message
    d = data("stewart_rotary")
    d["home"]["ty"] = 0.40  # rods and cranks cannot reach
    err = error_for(d)
    assert err.key == "home" and "cannot reach" in err.message
    d = data("heave_pitch_roll")
    d["park"]["ty"] = 0.38
    err = error_for(d)
    assert err.key == "park" and "below its soft range" in err.message


def test_a_home_on_the_edge_leaves_no_room() -> None:
    d = data("heave_pitch_roll")
    d["home"]["ty"] = 0.405  # at the soft limit: no room to move down
    err = error_for(d)
    assert err.key == "home" and "no room" in err.message


def test_joint_and_actuator_shapes() -> None:
    d = data("heave_pitch_roll")
    d["joints"]["base"] = d["joints"]["base"][:2]
    assert error_for(d).key == "joints.base"
    d = data("stewart_linear")
    d["joints"]["base"] = [[0.8, 0.0, 0.0]] * 6
    assert error_for(d).key == "joints"  # a mix of the two forms
    d = data("stewart_linear")
    d["actuators"]["arm_length"] = 0.05
    err = error_for(d)
    assert err.key == "actuators.arm_length" and "not used" in err.message
    d = data("stewart_rotary")
    del d["actuators"]["rod_length"]
    assert error_for(d).key == "actuators.rod_length"
    d = data("stewart_linear")
    d["actuators"]["max_speed"] = [0.8] * 5
    assert error_for(d).key == "actuators.max_speed"
    d["actuators"]["max_speed"] = [0.8, 0.8, 0.8, 0.8, 0.8, -1.0]
    assert error_for(d).key == "actuators.max_speed"


def test_per_actuator_limits_are_kept() -> None:
    d = data("stewart_linear")
    d["actuators"]["max_speed"] = [0.8, 0.7, 0.8, 0.7, 0.8, 0.7]
    from riderlive.platform.mechanism.config import build_geometry

    assert build_geometry(platform_from_dict(d)).max_speed == (0.8, 0.7, 0.8, 0.7, 0.8, 0.7)


def test_the_three_axis_rig_is_held_by_its_guide() -> None:
    d = data("heave_pitch_roll")
    d["home"]["tx"] = 0.05
    err = error_for(d)
    assert err.key == "home.tx" and "guide holds it at 0" in err.message
    d = data("heave_pitch_roll")
    d["centre"] = {"ty": 0.4}
    assert error_for(d).key == "centre"


def test_ease_times_must_fit_the_limits() -> None:
    d = data("stewart_linear")
    d["actuators"]["max_speed"] = 0.1  # a full stroke at 0.1 m/s eased: >= 4.5 s
    d["park_s"] = 2.0
    err = error_for(d)
    assert err.key == "soft_start_s" and "too short" in err.message
    d = data("stewart_linear")
    d["park_s"] = 0.5
    assert error_for(d).key == "park_s"  # the schema's 1-5 s


def test_cueing_presets_and_overrides() -> None:
    d = data("stewart_linear")
    d["cueing"] = {"preset": "gentle", "intensity": 55.0}
    cfg = platform_from_dict(d)
    assert cfg.cueing.preset == "gentle" and cfg.cueing.intensity == 55.0
    assert cfg.cueing.tilt_rate_dps == PRESETS["gentle"].tilt_rate_dps
    d["cueing"] = {"preset": "wild"}
    err = error_for(d)
    assert err.key == "cueing" and "unknown preset" in err.message
    d["cueing"] = {"intensity": 120.0}
    assert error_for(d).key == "cueing.intensity"
    d["cueing"] = {"drift_cutoff_hz": 0.4, "washout_rotation_hz": 0.3}
    err = error_for(d)
    assert err.key == "cueing" and "washout_rotation_hz must be above drift_cutoff_hz" in err.message


def test_missing_and_broken_files(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="file not found"):
        load_platform(tmp_path / "nope.toml")
    broken = tmp_path / "broken.toml"
    broken.write_text("kind = \n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_platform(broken)
    d = data("stewart_linear")
    d["kind"] = "hexapod"
    assert error_for(d).key == "kind"


def test_limits_too_slow_for_the_firmwares_park_are_refused() -> None:
    """The firmware parks at 25 % of max_speed: over a full stroke that must end within 5 s."""
    cfg = load_platform("stewart_linear")
    assert platform_problems(cfg) == []
    slow = cfg.model_copy(update={"actuators": cfg.actuators.model_copy(update={"max_speed": 0.05})})
    g = build_geometry(slow)
    stroke = max(hi - lo for lo, hi in zip(g.lower, g.upper, strict=True))
    # brake from 0.05 m/s at 20 m/s^2, then the stroke at 0.0125 m/s (+ its own ramps)
    expected = 0.05 / 20.0 + stroke / 0.0125 + 0.0125 / 20.0
    assert expected > 5.0
    problems = dict(platform_problems(slow))
    assert problems["actuators.max_speed"] == (
        f"too slow for the firmware's dead-man park: at 25% of max_speed over a full stroke it takes "
        f"{expected:.2f} s, at most 5 s (raise max_speed or max_accel)"
    )
