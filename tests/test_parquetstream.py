"""Parquet in chunks: the streamed bake equals the whole-take bake, and errors name the file's row."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import polars as pl
import pytest

from riderlive.bake import bake_chunks, bake_table
from riderlive.channels import HORSE_NAMES, RIDER_NAMES
from riderlive.cli import main
from riderlive.framefile import FrameFileError, FrameTable, read_frames
from riderlive.parquetstream import open_parquet, read_chunks, write_chunks
from riderlive.rules.engine import RiderModel
from riderlive.rules.params import FollowThrough, RuleParams, Smoothing
from tests.test_bake import horse_take


def write_take(path: Path, n: int, with_time: bool = True, seed: int = 0) -> np.ndarray:
    horse = horse_take(n, seed)
    columns = {"t": np.cumsum(np.random.default_rng(seed).uniform(0.001, 0.02, n))} if with_time else {}
    pl.DataFrame(columns | {name: horse[:, i] for i, name in enumerate(HORSE_NAMES)}).write_parquet(path)
    return horse


@pytest.mark.parametrize("with_time", [True, False])
@pytest.mark.parametrize("compiled", [False, True])
def test_streamed_bake_equals_the_whole_take_with_filters_on(tmp_path: Path, with_time: bool, compiled: bool) -> None:
    src, out = tmp_path / "horse.parquet", tmp_path / "rider.parquet"
    write_take(src, 500, with_time)
    params = RuleParams(smoothing=Smoothing(time_constant=0.03), follow_through=FollowThrough(frequency=2.0))
    model = RiderModel(params=params, scale=1.3)
    whole = bake_table(read_frames(str(src)), model, rate=90.0)
    take = open_parquet(str(src))
    assert take.frames == 500 and take.channels == HORSE_NAMES
    names = list(RIDER_NAMES[::3])
    chunks = bake_chunks(read_chunks(take, chunk=37), model, names, 90.0, compiled)
    seen: list[int] = []
    write_chunks(str(out), ["t", *names], chunks, progress=seen.append)
    assert sum(seen) == 500 and len(seen) == 14  # 13 chunks of 37 and one of 19
    streamed = read_frames(str(out))
    assert streamed.names == tuple(names) and streamed.t is not None
    np.testing.assert_array_equal(streamed.t, whole.times(90.0))
    expected = whole.values[:, [RIDER_NAMES.index(n) for n in names]]
    np.testing.assert_allclose(streamed.values, expected, rtol=0, atol=1e-12)


def test_cli_streams_parquet_to_parquet_as_the_csv_path_bakes(tmp_path: Path) -> None:
    write_take(tmp_path / "horse.parquet", 300, seed=4)
    assert main(["bake", str(tmp_path / "horse.parquet"), "-o", str(tmp_path / "rider.csv")]) == 0  # whole take
    assert main(["bake", str(tmp_path / "horse.parquet"), "-o", str(tmp_path / "rider.parquet")]) == 0  # streamed
    whole, streamed = read_frames(str(tmp_path / "rider.csv")), read_frames(str(tmp_path / "rider.parquet"))
    assert streamed.names == RIDER_NAMES == whole.names and streamed.t is not None and whole.t is not None
    np.testing.assert_allclose(streamed.values, whole.values, rtol=0, atol=1e-12)
    np.testing.assert_allclose(streamed.t, whole.t, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    ("row", "value", "message"),
    [(1, None, "empty cell"), (100, np.nan, "not finite: nan"), (129, np.inf, "not finite: inf")],
)
def test_a_bad_cell_in_a_later_chunk_is_named_by_its_row_in_the_file(
    tmp_path: Path, row: int, value: float | None, message: str
) -> None:
    write_take(tmp_path / "horse.parquet", 200)
    frame = pl.read_parquet(tmp_path / "horse.parquet")
    cells = frame["lbHoof.tz"].to_list()
    cells[row - 1] = value
    frame.with_columns(pl.Series("lbHoof.tz", cells, dtype=pl.Float64)).write_parquet(tmp_path / "bad.parquet")
    take = open_parquet(str(tmp_path / "bad.parquet"))
    with pytest.raises(FrameFileError) as err:
        for _ in read_chunks(take, chunk=32):
            pass
    assert err.value.row == row and err.value.column == "lbHoof.tz" and message in str(err.value)


def test_a_failure_mid_stream_propagates_and_leaves_the_target_alone(tmp_path: Path) -> None:
    out = tmp_path / "rider.parquet"
    out.write_bytes(b"previous take")

    def chunks() -> object:
        yield {"t": np.arange(3.0), "head.rz": np.ones(3)}
        raise FrameFileError("horse.parquet", "not finite: nan", row=4, column="t")

    with pytest.raises(FrameFileError, match="row 4: column 't'"):
        write_chunks(str(out), ["t", "head.rz"], chunks())  # type: ignore[arg-type]
    assert out.read_bytes() == b"previous take" and [p.name for p in tmp_path.iterdir()] == ["rider.parquet"]


def test_write_chunks_writes_standard_parquet_row_groups(tmp_path: Path) -> None:
    out = tmp_path / "x.parquet"
    parts = [{"t": np.arange(a, b, dtype=float), "head.rz": np.arange(a, b) * 0.5} for a, b in [(0, 5), (5, 9)]]
    write_chunks(str(out), ["t", "head.rz"], parts)
    table = read_frames(str(out))
    assert isinstance(table, FrameTable) and table.t is not None
    np.testing.assert_array_equal(table.t, np.arange(9.0))
    np.testing.assert_array_equal(table.column("head.rz"), np.arange(9) * 0.5)
