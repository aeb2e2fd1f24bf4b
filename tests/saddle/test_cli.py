"""``riderlive saddle`` and ``riderlive bake`` of a saddle take, through the command line.

One test runs the installed command in a subprocess; the rest call the same
``riderlive.cli.main`` in-process (no interpreter start-up per call).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from riderlive.channels import HORSE_NAMES, RIDER_INDEX, SADDLE_NAMES
from riderlive.cli import main
from riderlive.framefile import read_frames
from riderlive.horse import DEFAULT_SCALE, generate_gait
from riderlive.rules import RiderModel
from riderlive.saddle.pose import SaddlePoint, saddle_matrix
from tests.test_bake import run_cli


@pytest.fixture
def cli(capsys: pytest.CaptureFixture[str]):
    def call(*args: str) -> tuple[int, str]:
        code = main(list(args))
        return code, capsys.readouterr().err

    return call


def test_saddle_of_a_horse_take_and_of_the_procedural_horse_agree(tmp_path: Path, cli) -> None:
    horse, out = tmp_path / "horse.csv", tmp_path / "saddle.jsonl"
    assert cli("horse", "--gait", "canter", "--seconds", "2", "-o", str(horse))[0] == 0
    code, err = cli("saddle", str(horse), "-o", str(out), "--forward", "0.5", "--up", "0.1")
    assert code == 0, err
    saddle = read_frames(str(out))
    assert saddle.names == SADDLE_NAMES
    expected = saddle_matrix(generate_gait("canter", 2.0).values, SaddlePoint(forward=0.5, up=0.1))
    np.testing.assert_allclose(saddle.values, expected, atol=1e-12)
    direct = tmp_path / "direct.csv"
    code, err = cli(
        "saddle", "--gait", "canter", "--seconds", "2", "--forward", "0.5", "--up", "0.1", "-o", str(direct)
    )
    assert code == 0, err
    np.testing.assert_allclose(read_frames(str(direct)).values, expected, atol=1e-12)


def test_a_strap_recording_baked_into_a_rider_and_rebuilt_into_a_horse(tmp_path: Path, cli) -> None:
    rec, rider, horse = tmp_path / "rec.csv", tmp_path / "rider.csv", tmp_path / "horse.csv"
    code, err = cli("saddle", "--gait", "trot", "--seconds", "6", "--imu-strap", "--seed", "2", "-o", str(rec))
    assert code == 0, err
    recording = read_frames(str(rec))
    assert 0.85 < len(recording) / 720 < 0.95  # 10 % dropped
    result = run_cli("bake", str(rec), "--saddle", "-o", str(rider))  # the installed command, end to end
    assert result.returncode == 0, result.stderr
    baked = read_frames(str(rider))
    assert baked.names[-6:] == SADDLE_NAMES and baked.names[0] == "lower_back.rz"
    np.testing.assert_array_equal(baked.values[:, -6:], recording.values)  # the saddle as recorded
    code, err = cli("saddle", "--rebuild", str(rec), "-o", str(horse))
    assert code == 0, err
    assert "locked:trot" in err and "counters:" in err
    rebuilt = read_frames(str(horse))
    assert rebuilt.names == HORSE_NAMES
    rider_model = RiderModel(scale=DEFAULT_SCALE)  # a saddle take bakes with 25 units per metre
    expected = rider_model.evaluate_batch(rebuilt.values)[:, RIDER_INDEX["lower_back.rz"]]
    np.testing.assert_allclose(baked.values[:, 0], expected, atol=1e-9)


def test_bake_writes_the_saddle_of_a_horse_take(tmp_path: Path, cli) -> None:
    horse, rider = tmp_path / "horse.csv", tmp_path / "rider.csv"
    assert cli("horse", "--gait", "walk", "--seconds", "1", "-o", str(horse))[0] == 0
    code, err = cli("bake", str(horse), "--scale", "25", "--channels", "cog.ty", "--saddle", "-o", str(rider))
    assert code == 0, err
    baked = read_frames(str(rider))
    assert baked.names == ("cog.ty", *SADDLE_NAMES)
    np.testing.assert_allclose(baked.values[:, 1:], saddle_matrix(generate_gait("walk", 1.0).values), atol=1e-12)


def test_bad_saddle_input_and_options_are_clear_errors(tmp_path: Path, cli) -> None:
    partial = tmp_path / "partial.csv"
    partial.write_text("t,saddle.tx,saddle.ty\n0,0,0\n")
    code, err = cli("bake", str(partial), "-o", str(tmp_path / "x.csv"))
    assert code == 2 and "missing required channel(s): lfHoof.tx" in err
    code, err = cli("saddle", "--rebuild", str(partial), "-o", str(tmp_path / "y.csv"))
    assert code == 2 and "saddle.tz" in err
    code, err = cli("saddle", "--gait", "trot", "--forward", "2", "-o", str(tmp_path / "z.csv"))
    assert code == 2 and "forward" in err and "0.95" in err
    code, err = cli("saddle", "--gait", "trot", "--rate", "5", "-o", str(tmp_path / "z.csv"))
    assert code == 2 and "10-1000 Hz" in err
    nan = tmp_path / "nan.csv"
    nan.write_text("t," + ",".join(SADDLE_NAMES) + "\n0,0,0,0,0,0,0\n0.01,0,nan,0,0,0,0\n")
    code, err = cli("bake", str(nan), "-o", str(tmp_path / "w.csv"))
    assert code == 2 and "nan.csv:3" in err and "saddle.ty" in err
    assert not (tmp_path / "w.csv").exists()
