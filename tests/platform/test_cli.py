"""``riderlive platform``: describe a platform, bake a horse or saddle take to tracks and a plot."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from riderlive.cli import main
from riderlive.framefile import FrameTable, read_frames, write_frames
from riderlive.horse import gait_script, generate
from riderlive.platform.saddle_input import SADDLE_CHANNELS, saddle_pose


def test_info_describes_the_platform(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["platform", "stewart_rotary", "--info"]) == 0
    out = capsys.readouterr().out
    assert "kind stewart_rotary, carries a puppet (10 kg), 6 actuators" in out
    assert "home positions" in out and "park positions" in out
    assert len([line for line in out.splitlines() if line.startswith(("tx ", "rz "))]) == 2


def test_bake_a_horse_take_to_tracks_and_a_plot(tmp_path: Path) -> None:
    take = tmp_path / "trot.csv"
    write_frames(str(take), generate(gait_script("trot", 3.0), rate=100.0))
    tracks, png = tmp_path / "tracks.csv", tmp_path / "tracks.png"
    assert main(["platform", "heave_pitch_roll", str(take), "-o", str(tracks), "--plot", str(png)]) == 0
    table = read_frames(str(tracks))
    assert table.names == (
        "platform.tx", "platform.ty", "platform.tz", "platform.rx", "platform.ry", "platform.rz",
        "platform.a1", "platform.a2", "platform.a3",
    )  # fmt: skip
    assert len(table) == 300 and table.t is not None and table.t[1] == pytest.approx(0.01)
    assert np.all(table.values[:, [0, 2, 4]] == 0.0)  # the rig's guide holds surge, sway and yaw
    assert np.all((table.values[:, 6:] >= 0.005) & (table.values[:, 6:] <= 0.195))
    assert png.stat().st_size > 10_000 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_saddle_frames_are_used_as_they_are() -> None:
    values = np.arange(24, dtype=float).reshape(4, 6)
    table = FrameTable((*SADDLE_CHANNELS, "lfHoof.tx"), np.hstack([values, np.zeros((4, 1))]))
    np.testing.assert_array_equal(saddle_pose(table), values)


def test_bad_input_exits_2_and_writes_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "tracks.csv"
    assert main(["platform", "no_such_platform", "x.csv", "-o", str(out)]) == 2
    assert "file not found" in capsys.readouterr().err
    assert main(["platform", "stewart_linear", str(tmp_path / "missing.csv"), "-o", str(out)]) == 2
    rider = tmp_path / "rider.csv"
    rider.write_text("t,lower_back.rz\n0,1\n0.01,2\n")
    assert main(["platform", "stewart_linear", str(rider), "-o", str(out)]) == 2
    assert "needs the saddle channels" in capsys.readouterr().err
    assert main(["platform", "stewart_linear", str(rider)]) == 2
    assert main(["platform", "stewart_linear", "--preset", "wild", "--info"]) == 2
    assert "unknown cueing preset" in capsys.readouterr().err
    assert main(["platform", "stewart_linear", "--intensity", "150", "--info"]) == 2
    assert not out.exists()


def _tracks(tmp_path: Path, take: Path, *flags: str) -> np.ndarray:
    out = tmp_path / f"tracks{len(list(tmp_path.iterdir()))}.csv"
    assert main(["platform", "stewart_compact", str(take), "-o", str(out), *flags]) == 0
    return read_frames(str(out)).values


def test_the_saddle_point_is_the_live_services_and_lengths_come_in_their_recorded_unit(tmp_path: Path) -> None:
    from riderlive.channels import HORSE_NAMES
    from riderlive.framefile import horse_matrix
    from riderlive.frameunits import record_scale
    from riderlive.platform.cli import tracks_table
    from riderlive.platform.mechanism.pipeline import PlatformModel, bake
    from riderlive.saddle import SaddlePoint, saddle_from_horse

    table = generate(gait_script("canter", 2.0), rate=100.0)
    take = tmp_path / "canter.csv"
    write_frames(str(take), table)
    service = tmp_path / "service.toml"
    service.write_text("[tick]\nrate = 100.0\n[saddle]\nforward = 0.9\nup = 0.3\n")
    # the oracle: the scalar saddle pose of each frame at that point, through the platform's pipeline
    point = SaddlePoint(forward=0.9, up=0.3)
    saddle = np.array([saddle_from_horse(row, point) for row in horse_matrix(table)])
    model = PlatformModel.load("stewart_compact")
    times = table.times(100.0)
    dt = np.diff(times, prepend=times[0] - (times[1] - times[0]))
    expected = tracks_table(model, bake(model, saddle, dt), times).values

    configured = _tracks(tmp_path, take, "--config", str(service))
    np.testing.assert_allclose(configured, expected, atol=1e-9)
    np.testing.assert_allclose(_tracks(tmp_path, take, "--forward", "0.9", "--up", "0.3"), expected, atol=1e-9)
    default = _tracks(tmp_path, take)
    assert np.abs(default[:, 6:] - configured[:, 6:]).max() > 1e-3  # the saddle point moves the actuators by mm

    # the same take in decimetres, its unit recorded beside it (or given): the same tracks
    dm = FrameTable(table.names, table.values.copy(), table.t)
    lengths = [j for j, n in enumerate(dm.names) if n in HORSE_NAMES and n.split(".")[1].startswith("t")]
    dm.values[:, lengths] *= 10.0
    take_dm = tmp_path / "canter_dm.csv"
    write_frames(str(take_dm), dm)
    np.testing.assert_allclose(
        _tracks(tmp_path, take_dm, "--config", str(service), "--scale", "2.5"), expected, atol=1e-7
    )
    record_scale(str(take_dm), 2.5)
    np.testing.assert_allclose(_tracks(tmp_path, take_dm, "--config", str(service)), expected, atol=1e-7)


def test_a_bad_saddle_point_names_the_file_and_key(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    take = tmp_path / "trot.csv"
    write_frames(str(take), generate(gait_script("trot", 0.5), rate=100.0))
    service = tmp_path / "service.toml"
    service.write_text("[saddle]\nforward = 2.0\n")
    assert (
        main(["platform", "stewart_compact", str(take), "-o", str(tmp_path / "o.csv"), "--config", str(service)]) == 2
    )
    err = capsys.readouterr().err
    assert f"{service} [saddle]: forward" in err and "0.95" in err
    assert main(["platform", "stewart_compact", str(take), "-o", str(tmp_path / "o.csv"), "--up", "9"]) == 2
    assert "--up): up" in capsys.readouterr().err
