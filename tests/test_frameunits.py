"""The tour's traps: a frame file's length unit is recorded and read; the examples fail in one line."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from riderlive.bake import bake_table
from riderlive.cli import main
from riderlive.framefile import FrameTable, read_frames, write_frames
from riderlive.frameunits import METRES, looks_like_metres, recorded_scale, rescale_lengths, resolve_scale
from riderlive.rules import RiderModel, load_preset

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def trot(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("units") / "trot.csv"
    assert main(["horse", "--gait", "trot", "--seconds", "2", "-o", str(path)]) == 0
    return path


def test_the_horse_command_records_metres_and_bake_reads_them(trot: Path, tmp_path: Path, capsys) -> None:
    assert json.loads(trot.with_suffix(".json").read_text())["length_scale"] == METRES
    assert main(["bake", str(trot), "-o", str(tmp_path / "rider.csv")]) == 0
    assert "warning" not in capsys.readouterr().err
    baked = read_frames(str(tmp_path / "rider.csv"))
    expected = bake_table(read_frames(str(trot)), RiderModel(params=load_preset("kuhnel2003"), scale=METRES))
    np.testing.assert_allclose(baked.values, expected.values, atol=1e-12, err_msg="bake without --scale reads metres")


def test_bake_and_plot_agree_on_the_scale_and_warn_alike(trot: Path, tmp_path: Path, capsys) -> None:
    bare = tmp_path / "bare.csv"
    write_frames(str(bare), read_frames(str(trot)))  # the same metres, no sidecar
    assert recorded_scale(str(bare)) is None and looks_like_metres(read_frames(str(bare)))
    assert main(["bake", str(bare), "-o", str(tmp_path / "r.csv")]) == 0
    bake_err = capsys.readouterr().err
    assert "looks like metres" in bake_err and "--scale 25" in bake_err
    assert main(["plot", str(bare), "--bake", "--channels", "head.rz", "-o", str(tmp_path / "p.png")]) == 0
    assert "looks like metres" in capsys.readouterr().err
    assert main(["bake", str(bare), "--scale", "25", "-o", str(tmp_path / "r.csv")]) == 0
    assert "warning" not in capsys.readouterr().err
    assert main(["bake", str(trot), "--scale", "1", "-o", str(tmp_path / "r.csv")]) == 0
    assert "overrides length_scale 25" in capsys.readouterr().err
    for flag in (None, 3.0):
        assert resolve_scale(str(trot), read_frames(str(trot)), flag)[0] == (flag or METRES)


def test_thesis_unit_files_stay_quiet(tmp_path: Path) -> None:
    horse = np.zeros((10, 4))
    horse[:, 1] = np.linspace(0.0, 6.0, 10)  # rig units: hooves rise several units
    table = FrameTable(("lfHoof.tx", "lfHoof.ty", "rearPivot.rz", "rfHoof.ty"), horse)
    assert not looks_like_metres(table)
    assert resolve_scale(str(tmp_path / "rig.csv"), table, None) == (1.0, None)
    doubled = rescale_lengths(table, 2.0)
    assert doubled.values[5, 1] == 2 * horse[5, 1] and doubled.values[5, 2] == horse[5, 2], "rotations kept"


def run_example(*args: str, timeout: float = 20.0) -> tuple[subprocess.CompletedProcess[str], float]:
    start = time.perf_counter()
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    result = subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=timeout, cwd=ROOT, env=env)
    return result, time.perf_counter() - start


def test_a_wrong_url_is_a_one_line_error_not_a_traceback_or_a_hang(trot: Path, tmp_path: Path) -> None:
    closed = socket.socket()
    closed.bind(("127.0.0.1", 0))
    closed_port = closed.getsockname()[1]
    closed.close()
    silent = socket.socket()  # accepts, never answers
    silent.bind(("127.0.0.1", 0))
    silent.listen(1)
    try:
        cases = [
            (["examples/record_rider.py", str(tmp_path / "o.csv")], f"ws://127.0.0.1:{closed_port}"),
            (["examples/stream_horse_csv.py", str(trot)], f"ws://127.0.0.1:{closed_port}"),
            (["examples/record_rider.py", str(tmp_path / "o.csv")], "http://127.0.0.1:1"),
            (["examples/stream_horse_csv.py", str(trot)], f"ws://127.0.0.1:{silent.getsockname()[1]}"),
        ]
        for args, url in cases:
            result, took = run_example(*args, "--url", url, "--timeout", "0.5")
            assert result.returncode == 2, result.stderr
            lines = result.stderr.strip().splitlines()
            assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
            assert "cannot reach riderlive at" in lines[0] and url in lines[0]
            assert took < 10.0
    finally:
        silent.close()
