"""``riderlive plot`` renders a take (and its baked rider) to an image of the asked size."""

from __future__ import annotations

from pathlib import Path

import matplotlib.image
import pytest

from riderlive.cli import main


@pytest.fixture(scope="module")
def take(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("plot") / "walk.csv"
    assert main(["horse", "--gait", "walk", "--seconds", "3", "-o", str(path)]) == 0
    return path


def test_plot_with_bake_writes_a_png_of_the_asked_size(take: Path, tmp_path: Path) -> None:
    out = tmp_path / "walk.png"
    args = ["plot", str(take), "--bake", "--channels", "lower_back.rz,rearPivot.rz,cog.ty", "-o", str(out)]
    assert main([*args, "--size", "900x500", "--dpi", "80", "--title", "walk"]) == 0
    image = matplotlib.image.imread(out)
    assert image.shape[:2] == (500, 900)
    assert image[..., :3].std() > 0.05  # not blank


def test_rider_channel_needs_bake(take: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["plot", str(take), "--channels", "cog.ty", "-o", str(tmp_path / "x.png")]) == 2
    assert "--bake" in capsys.readouterr().err


def test_unknown_channel_is_an_error(take: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["plot", str(take), "--channels", "tail.rz", "-o", str(tmp_path / "x.png")]) == 2
    assert "unknown channel 'tail.rz'" in capsys.readouterr().err
    assert not (tmp_path / "x.png").exists()


def test_plot_a_rider_take_without_hooves(take: Path, tmp_path: Path) -> None:
    rider, out = tmp_path / "rider.csv", tmp_path / "rider.svg"
    assert main(["bake", str(take), "--scale", "25", "-o", str(rider)]) == 0
    assert main(["plot", str(rider), "--channels", "lower_back.rz,cog.ty", "-o", str(out)]) == 0
    assert out.read_text().lstrip().startswith("<?xml")
