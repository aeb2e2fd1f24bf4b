"""Takes on disk: readable frame files, flushed in whole lines, safe names."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest

from riderlive.channels import HORSE_NAMES, RIDER_NAMES
from riderlive.framefile import read_frames
from riderlive.takes import TakeRecorder, list_takes, load_replay, take_path


def test_a_take_is_a_frame_file_with_t_horse_and_rider(tmp_path: Path) -> None:
    rec = TakeRecorder(tmp_path / "a.csv", flush_interval=10.0, meta={"tick_rate": 100.0})
    rng = np.random.default_rng(1)
    rows = rng.normal(size=(50, len(HORSE_NAMES) + len(RIDER_NAMES)))
    for i, row in enumerate(rows):
        rec.add(5.0 + i / 100, row[: len(HORSE_NAMES)], row[len(HORSE_NAMES) :])
    rec.close()
    table = read_frames(str(tmp_path / "a.csv"))
    assert table.names == HORSE_NAMES + RIDER_NAMES
    np.testing.assert_array_equal(table.values, rows), "repr round-trips float64 exactly"
    np.testing.assert_allclose(table.t, np.arange(50) / 100, atol=1e-12)
    meta = json.loads((tmp_path / "a.json").read_text())
    assert meta == {"tick_rate": 100.0, "engine_t0": 5.0, "rows": 50}
    replay = load_replay(tmp_path / "a.csv")
    np.testing.assert_array_equal(replay.horse, rows[:, : len(HORSE_NAMES)])


def test_rows_reach_the_file_within_the_flush_interval_in_whole_lines(tmp_path: Path) -> None:
    rec = TakeRecorder(tmp_path / "b.csv", flush_interval=0.05)
    zeros_h, zeros_r = [0.0] * len(HORSE_NAMES), [0.0] * len(RIDER_NAMES)
    rec.add(0.0, zeros_h, zeros_r)
    assert (tmp_path / "b.csv").read_text().count("\n") == 1, "only the header before the first flush"
    time.sleep(0.06)
    rec.add(0.01, zeros_h, zeros_r)
    text = (tmp_path / "b.csv").read_text()
    assert text.count("\n") == 3 and text.endswith("\n"), "never a partial line on disk"
    assert len(read_frames(str(tmp_path / "b.csv"))) == 2
    rec.close()


def test_take_names_cannot_escape_the_directory(tmp_path: Path) -> None:
    assert take_path(tmp_path, "ok-1.2_x") == tmp_path / "ok-1.2_x.csv"
    assert take_path(tmp_path, "ok.csv") == tmp_path / "ok.csv"
    for bad in ("../x", "a/b", "", ".hidden", "a..b", "x" * 200):
        with pytest.raises(ValueError):
            take_path(tmp_path, bad)


def test_list_takes_newest_first(tmp_path: Path) -> None:
    assert list_takes(tmp_path / "missing") == []
    for name in ("one", "two"):
        TakeRecorder(tmp_path / f"{name}.csv").close()
        time.sleep(0.01)
    assert [t["name"] for t in list_takes(tmp_path)] == ["two", "one"]
