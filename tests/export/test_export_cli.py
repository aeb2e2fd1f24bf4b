"""``riderlive export``: files written, and bad input refused with a clear error and nothing written."""

from __future__ import annotations

from pathlib import Path

import pytest

from riderlive.cli import main
from riderlive.takes.recorder import TakeRecorder
from tests.export.conftest import write_take


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str]:
    code = main(["export", *argv])
    return code, capsys.readouterr().err


def test_a_take_by_name_becomes_two_bvh_files_and_one_glb(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    takes = tmp_path / "takes"
    takes.mkdir()
    write_take(takes, "jump", seconds=0.5)
    code, err = _run(capsys, "jump", "--takes", str(takes), "--format", "bvh", "-o", str(tmp_path / "out"))
    assert code == 0, err
    assert (tmp_path / "out.rider.bvh").read_text().startswith("HIERARCHY\nROOT rider\n")
    assert (tmp_path / "out.horse.bvh").read_text().startswith("HIERARCHY\nROOT root\n")
    assert "60 frames at 120 Hz" in err
    code, err = _run(capsys, str(takes / "jump.csv"), "--format", "gltf", "-o", str(tmp_path / "jump.glb"))
    assert code == 0, err
    assert (tmp_path / "jump.glb").read_bytes()[:4] == b"glTF"
    code, _ = _run(capsys, str(takes / "jump.csv"), "--format", "bvh", "--unit", "cm", "-o", str(tmp_path / "cm"))
    assert code == 0
    line = (tmp_path / "cm.rider.bvh").read_text().splitlines()[7]
    assert line.split() == ["OFFSET", "0.000000", "10.000000", "0.000000"]  # hips 0.10 m above the seat


def _nothing_written(directory: Path, before: set[Path]) -> bool:
    return set(directory.rglob("*")) == before


@pytest.mark.parametrize("fmt", ["bvh", "gltf"])
def test_a_missing_take_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str], fmt: str) -> None:
    before = set(tmp_path.rglob("*"))
    code, err = _run(capsys, "nope", "--takes", str(tmp_path), "--format", fmt, "-o", str(tmp_path / "x"))
    assert code == 2
    assert "no such take" in err
    assert _nothing_written(tmp_path, before)


def test_a_take_still_being_recorded_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    recorder = TakeRecorder(tmp_path / "live.csv", meta={"tick_rate": 120.0})
    recorder.add(0.0, [0.0] * 23, [0.0] * 37)
    recorder.flush()
    try:
        before = set(tmp_path.rglob("*"))
        code, err = _run(capsys, "live", "--takes", str(tmp_path), "--format", "gltf", "-o", str(tmp_path / "x.glb"))
        assert code == 2
        assert "still being recorded" in err
        assert _nothing_written(tmp_path, before)
    finally:
        recorder.close()
    code, err = _run(capsys, "live", "--takes", str(tmp_path), "--format", "gltf", "-o", str(tmp_path / "x.glb"))
    assert code == 0, err  # closed: exportable


@pytest.mark.parametrize(
    ("header", "row", "message"),
    [
        ("t,lfHoof.tx,neck.rz", "0,0,0", "column 'neck.rz': unknown channel"),
        ("t,lower_back.rz,hip.rz", "0,1,2", "lacks lower_back.ry"),
        ("t,tail_00.tx", "0,1", "no horse or rider channels"),
        ("t,lfHoof.tx", "0,nan", "not finite"),
    ],
)
def test_a_take_the_skeletons_cannot_pose_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], header: str, row: str, message: str
) -> None:
    take = tmp_path / "odd.csv"
    take.write_text(f"{header}\n{row}\n")
    before = set(tmp_path.rglob("*"))
    code, err = _run(capsys, str(take), "--format", "bvh", "-o", str(tmp_path / "odd"))
    assert code == 2
    assert message in err
    assert _nothing_written(tmp_path, before)


def test_a_missing_output_directory_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    write_take(tmp_path, "t", seconds=0.1)
    code, err = _run(capsys, str(tmp_path / "t.csv"), "--format", "gltf", "-o", str(tmp_path / "no" / "t.glb"))
    assert code == 2
    assert "no such directory" in err
