"""Takes on disk: readable frame files, flushed in whole lines, safe names."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np
import pytest

from riderlive.channels import HORSE_NAMES, RIDER_NAMES
from riderlive.framefile import read_frames
from riderlive.takes import TakeExists, TakeRecorder, list_takes, load_replay, recover_take, take_path


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
    started = meta.pop("started")
    assert meta == {"name": "a", "tick_rate": 100.0, "engine_t0": 5.0, "rows": 50, "complete": True}
    assert started.endswith("+00:00")
    replay = load_replay(tmp_path / "a.csv")
    np.testing.assert_array_equal(replay.horse, rows[:, : len(HORSE_NAMES)])


def test_rows_reach_the_file_within_the_flush_interval_in_whole_lines(tmp_path: Path) -> None:
    now = [100.0]
    rec = TakeRecorder(tmp_path / "b.csv", flush_interval=0.05, clock=lambda: now[0])
    zeros_h, zeros_r = [0.0] * len(HORSE_NAMES), [0.0] * len(RIDER_NAMES)
    rec.add(0.0, zeros_h, zeros_r)
    now[0] += 0.04
    rec.add(0.005, zeros_h, zeros_r)
    assert (tmp_path / "b.csv").read_text().count("\n") == 1, "only the header before the first flush"
    now[0] += 0.02  # past the flush interval since the recorder opened
    rec.add(0.01, zeros_h, zeros_r)
    text = (tmp_path / "b.csv").read_text()
    assert text.count("\n") == 4 and text.endswith("\n"), "never a partial line on disk"
    assert len(read_frames(str(tmp_path / "b.csv"))) == 3
    rec.close()


def test_take_names_cannot_escape_the_directory(tmp_path: Path) -> None:
    assert take_path(tmp_path, "ok-1_x") == tmp_path / "ok-1_x.csv"
    assert take_path(tmp_path, "x" * 64) == tmp_path / f"{'x' * 64}.csv"
    for bad in ("../x", "a/b", "", ".hidden", "a..b", "ok.csv", "x" * 65, "-x", "a b", "é", "a\n"):
        with pytest.raises(ValueError, match="1-64 of"):
            take_path(tmp_path, bad)


def test_list_takes_newest_first(tmp_path: Path) -> None:
    assert list_takes(tmp_path / "missing") == []
    for age, name in ((20.0, "one"), (10.0, "two")):
        TakeRecorder(tmp_path / f"{name}.csv").close()
        then = time.time() - age  # written that long ago (no waiting for the file system's clock)
        for path in tmp_path.glob(f"{name}.*"):
            os.utime(path, (then, then))
    assert [t["name"] for t in list_takes(tmp_path)] == ["two", "one"]


ZEROS_H, ZEROS_R = [0.0] * len(HORSE_NAMES), [0.0] * len(RIDER_NAMES)


def test_the_sidecar_is_written_at_start_and_kept_current(tmp_path: Path) -> None:
    rec = TakeRecorder(tmp_path / "live.csv", flush_interval=0.0, meta={"tick_rate": 120.0})
    meta = json.loads((tmp_path / "live.json").read_text())
    assert meta["rows"] == 0 and meta["complete"] is False and meta["tick_rate"] == 120.0
    for i in range(5):
        rec.add(10.0 + i / 120, ZEROS_H, ZEROS_R, monotonic=1000.0 + i / 120)
        meta = json.loads((tmp_path / "live.json").read_text())
        assert meta["rows"] == i + 1 == len(read_frames(str(tmp_path / "live.csv")))
    assert meta["engine_t0"] == 10.0 and meta["monotonic_t0"] == 1000.0 and meta["complete"] is False
    rec.close()
    assert json.loads((tmp_path / "live.json").read_text())["complete"] is True


def test_an_existing_take_is_never_overwritten_unless_asked(tmp_path: Path) -> None:
    old = TakeRecorder(tmp_path / "t.csv")
    for i in range(240):
        old.add(i / 120, ZEROS_H, ZEROS_R)
    old.close()
    with pytest.raises(TakeExists):
        TakeRecorder(tmp_path / "t.csv")
    assert len(read_frames(str(tmp_path / "t.csv"))) == 240, "a refused start changes nothing"
    new = TakeRecorder(tmp_path / "t.csv", overwrite=True)
    for i in range(24):
        new.add(i / 120, ZEROS_H, ZEROS_R)
    new.flush()
    assert len(read_frames(str(tmp_path / "t.csv"))) == 240, "the old take stays until the new one is complete"
    assert [t["name"] for t in list_takes(tmp_path)] == ["t"], "the new one is not listed while it records"
    new.close()
    assert len(read_frames(str(tmp_path / "t.csv"))) == 24
    assert json.loads((tmp_path / "t.json").read_text())["rows"] == 24
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.csv", "t.json"]


def test_overwriting_a_take_that_is_being_recorded_is_refused_at_once_and_changes_nothing(tmp_path: Path) -> None:
    """Two overwrites of one name while the first records (the fuzzer's case): the second
    must neither wait for the first's lock (it froze the web process) nor truncate its file."""
    first = TakeRecorder(tmp_path / "t.csv", overwrite=True, flush_interval=0.0)
    for i in range(24):
        first.add(i / 120, ZEROS_H, ZEROS_R)
    started = time.perf_counter()
    with pytest.raises(TakeExists, match="being recorded"):
        TakeRecorder(tmp_path / "t.csv", overwrite=True)
    assert time.perf_counter() - started < 0.5
    for i in range(24, 48):
        first.add(i / 120, ZEROS_H, ZEROS_R)
    first.close()
    assert len(read_frames(str(tmp_path / "t.csv"))) == 48, "the recording take lost nothing"


def test_a_take_cut_by_a_kill_is_recovered(tmp_path: Path) -> None:
    rec = TakeRecorder(tmp_path / "k.csv", flush_interval=0.0)
    for i in range(10):
        rec.add(i / 120, ZEROS_H, ZEROS_R)
    os.close(rec._fd)  # the process dies: no close(), and a write cut mid-line
    with (tmp_path / "k.csv").open("ab") as fh:
        fh.write(b"0.0833,0.0,0.")
    assert list_takes(tmp_path)[0]["complete"] is False
    assert recover_take(tmp_path / "k.csv") is True
    assert len(read_frames(str(tmp_path / "k.csv"))) == 10
    meta = json.loads((tmp_path / "k.json").read_text())
    assert meta["rows"] == 10 and meta["complete"] is True and meta["recovered"] is True
    assert recover_take(tmp_path / "k.csv") is False, "a complete take is left alone"
    assert len(load_replay(tmp_path / "k.csv").t) == 10
