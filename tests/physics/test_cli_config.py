"""``riderlive tail`` on a take file, and the physics config file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from riderlive.channels import HORSE_NAMES
from riderlive.cli import main
from riderlive.configfile import ConfigError
from riderlive.framefile import FrameTable, write_frames
from riderlive.physics import quaternion
from riderlive.physics.config import DEFAULT_FILE, PhysicsConfig, load_physics
from tests.physics.motion import horse_take


def test_shipped_config_matches_the_defaults() -> None:
    assert load_physics() == PhysicsConfig()
    assert DEFAULT_FILE.is_file()


def test_config_errors_name_the_key(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[skinned]\ntwist_rat = 3.0\n")
    with pytest.raises(ConfigError, match=r"skinned\.twist_rat.*unknown key"):
        load_physics(bad)
    bad.write_text("[reference.strand]\nbend = 0.9\n")
    with pytest.raises(ConfigError, match=r"reference\.strand\.bend"):
        load_physics(bad)


def _csv_fallback(path: Path) -> list[str]:
    return path.read_text().splitlines()[0].split(",")


def test_tail_command_writes_bone_channels(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    times, frames = horse_take("buck")
    keep = slice(0, 240, 4)  # one second at 60 Hz
    take = tmp_path / "buck.csv"
    write_frames(str(take), FrameTable(HORSE_NAMES, frames[keep], times[keep]))
    out = tmp_path / "tail.csv"
    assert main(["tail", str(take), "-o", str(out)]) == 0
    progress = capsys.readouterr().err.splitlines()  # before the first frame's compile, and once it is done
    assert progress[0].startswith("riderlive tail: compiling or loading the compiled physics")
    assert progress[1].startswith("riderlive tail: physics ready in ") and progress[1].endswith("; 60 frames")
    header = _csv_fallback(out)
    assert header[0] == "t" and "tail_00.qw" in header and "braid_10.rz" in header and "tail_10.fan" in header
    assert "tail_03.fan" not in header  # fan-out only on the lower half
    import polars as pl

    table = pl.read_csv(out)
    assert table.height == 60
    values = table.to_numpy()
    assert np.isfinite(values).all()
    for bone in ("tail_05", "braid_07"):
        q = table.select([f"{bone}.q{a}" for a in "xyzw"]).to_numpy()
        assert np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-9)
        euler = table.select([f"{bone}.r{a}" for a in "xyz"]).to_numpy()
        back = quaternion.from_euler_xyz(euler)
        assert np.allclose(np.abs(np.sum(back * q, axis=1)), 1.0, atol=1e-9)  # same rotation, either sign


def test_tail_command_reference_and_strands(tmp_path: Path) -> None:
    times, frames = horse_take("gallop")
    take = tmp_path / "gallop.jsonl"
    write_frames(str(take), FrameTable(HORSE_NAMES, frames[:60:6], times[:60:6]))
    out, npz = tmp_path / "out.jsonl", tmp_path / "strands.npz"
    assert main(["tail", str(take), "-o", str(out), "--reference", "--strands", str(npz), "--no-rider"]) == 0
    data = np.load(npz)
    assert data["vertices"].shape == (10, 12, 3, 400)
    assert out.read_text().count("tail_ref.tx") == 10


def test_tail_command_rejects_bad_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    take = tmp_path / "bad.csv"
    take.write_text("t,root.tx\n0,0\n0.1,nan\n")
    assert main(["tail", str(take), "-o", str(tmp_path / "o.csv")]) == 2
    assert "not finite" in capsys.readouterr().err
    assert not (tmp_path / "o.csv").exists()
    take.write_text("t,root.tx\n0.1,0\n0.1,1\n")
    assert main(["tail", str(take), "-o", str(tmp_path / "o.csv")]) == 2
    assert "increase" in capsys.readouterr().err
