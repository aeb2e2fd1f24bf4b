"""Shot scripts validate at load; ``riderlive horse`` writes takes that ``bake`` reads."""

from __future__ import annotations

from pathlib import Path

import pytest

from riderlive.cli import main
from riderlive.configfile import CONFIG_DIR, ConfigError
from riderlive.framefile import read_frames
from riderlive.horse import MOVE_TABLE, Move, load_script
from riderlive.rules.kuhnel2003 import RULE_INPUTS


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "shot.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("text", "key", "message"),
    [
        ('[[segment]]\ngait = "trot"\nmove = "jump"\nseconds = 1', "segment.0", "exactly one"),
        ('[[segment]]\ngait = "trot"', "segment.0", "needs 'seconds'"),
        ('[[segment]]\ngait = "trot"\nseconds = 2\nspeed = 9.0', "segment.0", "3.2-4.9"),
        ('[[segment]]\ngait = "amble"\nseconds = 2', "segment.0", "gait must be one of"),
        ('[[segment]]\nmove = "jump"\nspeed = 3.0', "segment.0", "own speed"),
        ('[[segment]]\ngait = "halt"\nseconds = 1\nspeed = 2.0', "segment.0", "halt has speed 0"),
        ('[[segment]]\ngait = "walk"\nseconds = -1', "segment.0.seconds", "greater than 0"),
        ('[[segment]]\ngait = "walk"\nseconds = nan', "segment.0.seconds", "finite"),
        ('tempo = 3\n[[segment]]\ngait = "walk"\nseconds = 1', "tempo", "unknown key"),
        ("name = 'empty'", "segment", "Field required"),
    ],
)
def test_bad_scripts_name_the_key(tmp_path: Path, text: str, key: str, message: str) -> None:
    with pytest.raises(ConfigError) as err:
        load_script(_write(tmp_path, text))
    assert err.value.key == key
    assert message in str(err.value)


def test_shipped_scripts_load() -> None:
    shots = sorted((CONFIG_DIR / "shots").glob("*.toml"))
    assert {p.stem for p in shots} >= {"jump", "rear", "stop", "buck", "ramp"}
    for shot in shots:
        assert load_script(shot).duration > 0.0


def test_move_segment_lasts_the_move_unless_told() -> None:
    script = load_script(CONFIG_DIR / "shots" / "stop.toml")
    assert script.duration == pytest.approx(2.5 + MOVE_TABLE[Move.STOP].duration + 3.0)


def test_cli_gait_take_feeds_bake(tmp_path: Path) -> None:
    take, rider = tmp_path / "trot.csv", tmp_path / "rider.csv"
    assert main(["horse", "--gait", "trot", "--seconds", "10", "--rate", "120", "-o", str(take)]) == 0
    table = read_frames(str(take), required=RULE_INPUTS)
    assert len(table) == 1200
    assert table.t is not None and table.t[1] == pytest.approx(1 / 120)
    assert main(["bake", str(take), "--scale", "25", "-o", str(rider)]) == 0
    assert len(read_frames(str(rider))) == 1200


def test_cli_script_take(tmp_path: Path) -> None:
    out = tmp_path / "shot.jsonl"
    assert main(["horse", "--script", str(CONFIG_DIR / "shots" / "stop.toml"), "--rate", "60", "-o", str(out)]) == 0
    table = read_frames(str(out))
    assert len(table) == round(load_script(CONFIG_DIR / "shots" / "stop.toml").duration * 60)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--gait", "trot", "--rate", "5"], "--rate"),
        (["--gait", "trot", "--speed", "12"], "3.2-4.9"),
        (["--script", "missing.toml"], "file not found"),
        (["--gait", "walk", "--seconds", "0"], "seconds must be within"),
    ],
)
def test_cli_errors_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], message: str) -> None:
    assert main(["horse", *args, "-o", str(tmp_path / "x.csv")]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x.csv").exists()
