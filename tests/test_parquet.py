"""Parquet takes: read and written by every command that handles frame files, bad input named like CSV's."""

from __future__ import annotations

import io
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import polars as pl
import pytest

from riderlive.channels import HORSE_NAMES, RIDER_NAMES
from riderlive.cli import main
from riderlive.framefile import FrameFileError, FrameTable, read_frames, write_frames
from riderlive.rules.engine import RiderModel
from riderlive.takes import load_replay, replay_path
from tests.test_bake import horse_take, read_csv, write_csv

Frame = dict[str, object]


def take_frame(n: int = 10, seed: int = 0) -> dict[str, object]:
    horse = horse_take(n, seed)
    return {"t": np.arange(n) / 100.0, **{name: horse[:, i] for i, name in enumerate(HORSE_NAMES)}}


def with_cell(name: str, row: int, value: object) -> Callable[[Frame], Frame]:
    """Set frame ``row`` (1 = the first frame) of column ``name``."""

    def mutate(columns: Frame) -> Frame:
        values = list(np.asarray(columns[name], dtype=object))
        values[row - 1] = value
        return {**columns, name: pl.Series(name, values, dtype=pl.Float64, strict=False)}

    return mutate


def test_round_trip_is_exact_and_columns_are_contiguous(tmp_path: Path) -> None:
    columns = take_frame(50)
    columns["lfHoof.tx"] = np.arange(50, dtype=np.int32)  # integer and float32 columns read as float64
    columns["rfHoof.tx"] = np.linspace(-1, 1, 50, dtype=np.float32)
    pl.DataFrame(columns).write_parquet(tmp_path / "in.parquet")
    table = read_frames(str(tmp_path / "in.parquet"))
    assert table.names == HORSE_NAMES and table.values.dtype == np.float64 and table.values.flags.f_contiguous
    np.testing.assert_array_equal(table.column("lfHoof.tx"), np.arange(50))
    np.testing.assert_array_equal(table.column("rfHoof.tx"), np.linspace(-1, 1, 50, dtype=np.float32))
    write_frames(str(tmp_path / "out.parquet"), table)
    again = read_frames(str(tmp_path / "out.parquet"))
    assert again.t is not None and table.t is not None
    np.testing.assert_array_equal(again.values, table.values)
    np.testing.assert_array_equal(again.t, table.t)
    assert not list(tmp_path.glob("*.part"))


@pytest.mark.parametrize(
    ("mutate", "expected", "csv_expected"),
    [
        (lambda c: {k: v for k, v in c.items() if k != "lfHoof.ty"}, "missing required channel(s): lfHoof.ty", None),
        (lambda c: {**c, "lfHoof.tw": np.ones(10)}, ": column 'lfHoof.tw': unknown channel", ":1: column 'lfHoof.tw'"),
        (lambda c: {**c, "lfHoof.tx": ["a"] * 10}, ": column 'lfHoof.tx': not numbers: the column holds String", None),
        (lambda c: {**c, "rearPivot.rz": [True] * 10}, ": column 'rearPivot.rz': not numbers", None),
        (with_cell("t", 4, float("nan")), ": row 4: column 't': not finite: nan", ":5: column 't': not finite"),
        (with_cell("rfHoof.ty", 2, -np.inf), ": row 2: column 'rfHoof.ty': not finite: -inf", ":3: column 'rfHoof.ty'"),
        (with_cell("rearPivot.rz", 6, None), ": row 6: column 'rearPivot.rz': empty cell", ":7: column 'rearPivot.rz'"),
    ],
)
def test_bad_parquet_exits_2_naming_row_and_column_as_csv_does(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    mutate: Callable[[Frame], Frame],
    expected: str,
    csv_expected: str | None,
) -> None:
    src, out = tmp_path / "bad.parquet", tmp_path / "rider.parquet"
    bad = pl.DataFrame(mutate(take_frame()), strict=False)
    bad.write_parquet(src)
    out.write_bytes(b"previous take")
    assert main(["bake", str(src), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{src}{expected}" in err or (str(src) in err and expected in err), err
    assert out.read_bytes() == b"previous take" and not list(tmp_path.glob("*.part"))
    if csv_expected is not None:  # the same take as CSV: the same column, the same frame (its line = row + 1)
        csv_src = tmp_path / "bad.csv"
        bad.write_csv(csv_src)
        assert main(["bake", str(csv_src), "-o", str(tmp_path / "r.csv")]) == 2
        assert csv_expected in capsys.readouterr().err


def test_not_a_parquet_file(tmp_path: Path) -> None:
    (tmp_path / "x.parquet").write_text("t,lfHoof.tx\n0,1\n")
    with pytest.raises(FrameFileError, match="not a Parquet file"):
        read_frames(str(tmp_path / "x.parquet"))
    with pytest.raises(FrameFileError, match="file not found"):
        read_frames(str(tmp_path / "none.parquet"))


def test_bake_parquet_to_parquet_equals_csv_and_says_where_time_goes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    horse = horse_take(300, seed=3)
    write_csv(tmp_path / "horse.csv", horse)
    write_frames(str(tmp_path / "horse.parquet"), read_frames(str(tmp_path / "horse.csv")))
    assert main(["bake", str(tmp_path / "horse.csv"), "-o", str(tmp_path / "rider.csv")]) == 0
    assert main(["bake", str(tmp_path / "horse.parquet"), "-o", str(tmp_path / "rider.parquet"), "--timings"]) == 0
    err = capsys.readouterr().err
    assert "300 frames in" in err and "read " in err and "rules " in err and "write " in err, err
    header, from_csv = read_csv(tmp_path / "rider.csv")
    table = read_frames(str(tmp_path / "rider.parquet"))
    assert table.names == RIDER_NAMES and header == ["t", *RIDER_NAMES]
    np.testing.assert_array_equal(table.values, from_csv[:, 1:])
    expected = np.array([RiderModel().evaluate(row) for row in horse.tolist()])
    np.testing.assert_allclose(table.values, expected, rtol=0.0, atol=1e-12)


def test_stdin_and_stdout_take_parquet(
    monkeypatch: pytest.MonkeyPatch, capsysbinary: pytest.CaptureFixture[bytes]
) -> None:
    data = io.BytesIO()
    pl.DataFrame(take_frame(20)).write_parquet(data)

    class Stdin:
        buffer = io.BytesIO(data.getvalue())

    monkeypatch.setattr(sys, "stdin", Stdin())
    assert main(["bake", "-", "-o", "-", "--format", "parquet"]) == 0
    out = pl.read_parquet(io.BytesIO(capsysbinary.readouterr().out))
    assert out.columns == ["t", *RIDER_NAMES] and out.height == 20


def test_plot_tail_and_replay_read_parquet(tmp_path: Path) -> None:
    from tests.physics.motion import horse_take as physics_take

    times, frames = physics_take("gallop")
    take = tmp_path / "gallop.parquet"
    write_frames(str(take), FrameTable(HORSE_NAMES, frames[:120:4], times[:120:4]))
    assert main(["plot", str(take), "--channels", "rearPivot.rz", "-o", str(tmp_path / "p.png")]) == 0
    assert (tmp_path / "p.png").stat().st_size > 0
    assert main(["tail", str(take), "-o", str(tmp_path / "tail.parquet"), "--no-rider"]) == 0
    assert read_frames(str(tmp_path / "tail.parquet")).names[0] == "tail_00.tx"
    assert replay_path(tmp_path, "gallop") == take  # no gallop.csv: the Parquet take replays
    replay = load_replay(replay_path(tmp_path, "gallop"))
    np.testing.assert_array_equal(replay.horse, frames[:120:4])
