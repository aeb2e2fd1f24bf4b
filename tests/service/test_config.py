"""The service config: the example file is the defaults (but the tail), errors name file and key."""

from __future__ import annotations

from pathlib import Path

import pytest

from riderlive.configfile import CONFIG_DIR, ConfigError
from riderlive.service.config import ServiceConfig, load_config


def test_the_example_file_loads_and_matches_the_defaults() -> None:
    example = load_config(CONFIG_DIR / "service.example.toml")
    assert example.physics.tail is True, "the example turns the tail on"
    assert not ServiceConfig().physics.tail, "off by default: the kernels compile on first use"
    assert example.model_copy(update={"physics": ServiceConfig().physics}) == ServiceConfig()
    assert load_config(None) == ServiceConfig()


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("[tick]\nrate = 5000.0\n", "tick.rate"),
        ("[tick]\nrate = nan\n", "tick.rate"),
        ("[input]\nholdd = 1.0\n", "input.holdd"),
        ("[source]\ngait = 'pace'\n", "source.gait"),
        ("[security]\ntoken = 'short'\n", "security.token"),
        ("[physics]\ntail = 'maybe'\n", "physics.tail"),
        ("[ranges]\nlength = [5.0, 1.0]\n", "ranges.length"),
        ("[ranges]\nchannels = { 'lfhoof.ty' = [0.0, 1.0] }\n", "ranges.channels"),
        ("[input]\nclock_jump = 0.0\n", "input.clock_jump"),
        ("[source]\ngait = 'walk'\nspeed = 4.0\n", "source.speed"),
        ("[tick]\nrate = 1000.0\nphase_margin = 0.0005\n", "tick.phase_margin"),
        ("[tick]\nphase_margin = -0.001\n", "tick.phase_margin"),
        ("[tick]\nphase_lock = 'sometimes'\n", "tick.phase_lock"),
        ("[tick]\nspare = 'maybe'\n", "tick.spare"),
        ("[host]\nkernel_workers_priority = 10\n", "host.kernel_workers_priority"),
        ("[host]\nkernel_workers_priority = -1\n", "host.kernel_workers_priority"),
        ("[host]\nkernel_workers = 1\n", "host.kernel_workers"),
    ],
)
def test_errors_name_the_file_and_key(tmp_path: Path, text: str, key: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_config(path)
    assert err.value.key == key and str(path) in str(err.value)


def test_a_rig_slower_than_the_tick_is_refused_when_asked_naming_both_rates(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from riderlive.cli import main

    config = tmp_path / "service.toml"
    config.write_text('[tick]\nrate = 120.0\n[rig]\nfile = "bench3"\nrate_policy = "refuse"\n')
    assert main(["serve", "--config", str(config), "--port", "0"]) == 2
    err = capsys.readouterr().err
    assert "bench3 is validated for 100 ticks/s but the service ticks at 120/s" in err


def test_a_gait_alone_runs_at_its_own_speed_and_a_speed_must_suit_its_gait(tmp_path: Path) -> None:
    path = tmp_path / "walk.toml"
    path.write_text("[source]\ngait = 'walk'\n")
    assert load_config(path).source.speed is None, "the walk's own speed, not a trot's 4 m/s"
    path.write_text("[source]\ngait = 'walk'\nspeed = 1.9\n")
    with pytest.raises(ConfigError, match=r"1\.4-1\.8"):
        load_config(path)
    path.write_text("[source]\ngait = 'gallop'\nspeed = 9.0\n")
    assert load_config(path).source.speed == 9.0


def test_the_phase_margin_must_be_less_than_half_a_period(tmp_path: Path) -> None:
    path = tmp_path / "margin.toml"
    path.write_text("[tick]\nrate = 1000.0\nphase_margin = 0.0005\n")
    with pytest.raises(ConfigError, match=r"0 <= phase_margin < 0\.000500 s at 1000 Hz"):
        load_config(path)
    path.write_text("[tick]\nrate = 1000.0\nphase_margin = 0.0004\n")
    assert load_config(path).tick.phase_margin == 0.0004
    assert ServiceConfig().tick.phase_lock is True


@pytest.mark.parametrize(
    ("text", "key", "message"),
    [
        ("slope = 45.0", "source.terrain.slope", r"less than or equal to 30 \(got 45\.0\)"),
        ("slope = nan", "source.terrain.slope", "finite number"),
        ("profile = [[0, 0], [10, 31]]", "source.terrain.profile", "knot 1: slope must be within -30-30 deg"),
        ("profile = [[0, 0], [0, 5]]", "source.terrain.profile", "knot 1: distances must increase strictly"),
        ("profile = []", "source.terrain.profile", "at least 1 item"),
        ("slope = 5.0\nprofile = [[0, 5]]", "source.terrain", r"exactly one of 'slope' \(deg\) or 'profile'"),
        ("height = 5.0", "source.terrain.height", "unknown key"),
    ],
)
def test_a_bad_source_terrain_names_file_key_and_range(tmp_path: Path, text: str, key: str, message: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(f"[source.terrain]\n{text}\n")
    with pytest.raises(ConfigError, match=message) as err:
        load_config(path)
    assert str(err.value).startswith(f"{path}: {key}: ")


def test_the_source_terrain_is_flat_unless_given(tmp_path: Path) -> None:
    assert ServiceConfig().source.terrain is None
    path = tmp_path / "hill.toml"
    path.write_text("[source.terrain]\nprofile = [[0, 0], [20, 8]]\n")
    terrain = load_config(path).source.terrain
    assert terrain is not None and terrain.profile == [(0.0, 0.0), (20.0, 8.0)] and terrain.slope is None
