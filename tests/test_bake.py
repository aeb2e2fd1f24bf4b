"""``riderlive bake`` end to end, through the real command line."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from riderlive.channels import HORSE_NAMES, RIDER_INDEX, RIDER_NAMES
from riderlive.rules.engine import RiderModel
from riderlive.rules.params import load_preset
from tests.cli_main import run_main


def run_cli(*args: str, stdin: str | None = None) -> subprocess.CompletedProcess[str]:
    """``riderlive ARGS`` as a process (the stdin/stdout and file-mode tests: the real wiring)."""
    return subprocess.run(
        [sys.executable, "-m", "riderlive", *args], input=stdin, capture_output=True, text=True, timeout=120
    )


def horse_take(n: int = 50, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(-5.0, 5.0, size=(n, len(HORSE_NAMES)))


def write_csv(path: Path, horse: np.ndarray, with_time: bool = True) -> None:
    with path.open("w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow((["t"] if with_time else []) + list(HORSE_NAMES))
        for i, row in enumerate(horse):
            writer.writerow(([f"{i / 100:.6f}"] if with_time else []) + [repr(float(v)) for v in row])


def read_csv(path: Path) -> tuple[list[str], np.ndarray]:
    with path.open() as fh:
        rows = list(csv.reader(fh))
    return rows[0], np.array(rows[1:], dtype=float)


def test_csv_bake_equals_the_engine(tmp_path: Path) -> None:
    horse = horse_take()
    src, out = tmp_path / "horse.csv", tmp_path / "rider.csv"
    write_csv(src, horse)
    result = run_main("bake", str(src), "-o", str(out))
    assert result.returncode == 0, result.stderr
    header, data = read_csv(out)
    assert header == ["t", *RIDER_NAMES]
    np.testing.assert_allclose(data[:, 0], np.arange(len(horse)) / 100, atol=1e-12)
    expected = np.array([RiderModel().evaluate(row) for row in horse.tolist()])
    np.testing.assert_allclose(data[:, 1:], expected, rtol=1e-12, atol=1e-12)


def test_jsonl_in_and_out_with_options(tmp_path: Path) -> None:
    horse = horse_take(20, seed=1)
    src, out, keys = tmp_path / "horse.jsonl", tmp_path / "rider.jsonl", tmp_path / "keys.toml"
    src.write_text(
        "".join(json.dumps({"t": i / 60, **dict(zip(HORSE_NAMES, row))}) + "\n" for i, row in enumerate(horse.tolist()))
    )
    keys.write_text('[offsets]\n"head.rz" = 1.5\n')
    result = run_main(
        "bake",
        str(src),
        "-o",
        str(out),
        "--preset",
        "english",
        "--scale",
        "2",
        "--channels",
        "head.rz,cog.ty",
        "--offsets",
        str(keys),
    )
    assert result.returncode == 0, result.stderr
    frames = [json.loads(line) for line in out.read_text().splitlines()]
    assert list(frames[0]) == ["t", "head.rz", "cog.ty"]
    model = RiderModel(params=load_preset("english"), scale=2.0)
    for frame, row in zip(frames, horse.tolist(), strict=True):
        expected = model.evaluate(row)
        assert frame["head.rz"] == pytest.approx(expected[RIDER_INDEX["head.rz"]] + 1.5, abs=1e-12)
        assert frame["cog.ty"] == pytest.approx(expected[RIDER_INDEX["cog.ty"]], abs=1e-12)


def test_stdin_to_stdout_and_missing_time_column() -> None:
    horse = horse_take(5, seed=2)
    text = ",".join(HORSE_NAMES) + "\n" + "".join(",".join(repr(float(v)) for v in row) + "\n" for row in horse)
    result = run_cli("bake", "-", "-o", "-", "--rate", "50", "--channels", "lower_back.rz", stdin=text)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0] == "t,lower_back.rz"
    assert [float(line.split(",")[0]) for line in lines[1:]] == pytest.approx([0.0, 0.02, 0.04, 0.06, 0.08])


def test_only_the_channels_the_rules_read_are_required(tmp_path: Path) -> None:
    from riderlive.rules.kuhnel2003 import RULE_INPUTS

    src, out = tmp_path / "minimal.csv", tmp_path / "rider.csv"
    src.write_text(",".join(RULE_INPUTS) + "\n" + ",".join(["1.0"] * len(RULE_INPUTS)) + "\n")
    result = run_main("bake", str(src), "-o", str(out))  # which channels: no process needed
    assert result.returncode == 0, result.stderr
    assert read_csv(out)[1].shape == (1, 1 + len(RIDER_NAMES))


COLUMNS = ["t", *HORSE_NAMES]


def set_cell(lines: list[str], line_no: int, column: str, text: str) -> list[str]:
    """Replace one cell; ``line_no`` counts from 1 like an editor (the header is line 1)."""
    cells = lines[line_no - 1].split(",")
    cells[COLUMNS.index(column)] = text
    return [*lines[: line_no - 1], ",".join(cells), *lines[line_no:]]


def drop_column(lines: list[str], column: str) -> list[str]:
    i = COLUMNS.index(column)
    return [",".join(c for j, c in enumerate(line.split(",")) if j != i) for line in lines]


CELLS = f":4: expected {len(HORSE_NAMES) + 1} cells, found {len(HORSE_NAMES) + 2}"


@pytest.mark.parametrize(
    ("mutate", "expected"),
    [
        (lambda lines: drop_column(lines, "lfHoof.ty"), "missing required channel(s): lfHoof.ty"),
        (lambda lines: set_cell(lines, 3, "lfHoof.tx", "abc"), ":3: column 'lfHoof.tx': not a number: 'abc'"),
        (lambda lines: set_cell(lines, 5, "t", "nan"), ":5: column 't': not finite: nan"),
        (lambda lines: set_cell(lines, 3, "rfHoof.ty", "-inf"), ":3: column 'rfHoof.ty': not finite: -inf"),
        (lambda lines: set_cell(lines, 7, "rearPivot.rz", ""), ":7: column 'rearPivot.rz': not a number: ''"),
        (
            lambda lines: [lines[0] + ",lfHoof.tw", *[line + ",1" for line in lines[1:]]],
            ":1: column 'lfHoof.tw': unknown channel",
        ),
        (lambda lines: [*lines[:3], lines[3] + ",1.0", *lines[4:]], CELLS),
    ],
)
def test_bad_input_exits_2_naming_line_and_column(tmp_path: Path, mutate, expected: str) -> None:  # type: ignore[no-untyped-def]
    src, out = tmp_path / "bad.csv", tmp_path / "rider.csv"
    write_csv(src, horse_take(10))
    src.write_text("\n".join(mutate(src.read_text().splitlines())) + "\n")
    out.write_text("previous take\n")
    result = run_main("bake", str(src), "-o", str(out))
    assert result.returncode == 2
    assert str(src) in result.stderr and expected in result.stderr, result.stderr
    assert out.read_text() == "previous take\n"  # nothing partial under the output's name
    assert not list(tmp_path.glob("*.part"))


def test_bad_jsonl_names_line(tmp_path: Path) -> None:
    src, out = tmp_path / "bad.jsonl", tmp_path / "rider.jsonl"
    good = json.dumps(dict.fromkeys(HORSE_NAMES, 0.0))
    src.write_text(good + "\n" + good.replace("0.0", '"x"', 1) + "\n")
    result = run_main("bake", str(src), "-o", str(out))
    assert result.returncode == 2 and ":2: column 'lfHoof.tx': not a number" in result.stderr
    src.write_text(good + "\n{not json\n")
    result = run_main("bake", str(src), "-o", str(out))
    assert result.returncode == 2 and ":2: not JSON" in result.stderr
    assert not out.exists()


def test_bad_options_exit_2(tmp_path: Path) -> None:
    src = tmp_path / "horse.csv"
    write_csv(src, horse_take(3))
    out = str(tmp_path / "r.csv")
    assert "unknown rider channel 'head.rq'" in run_main("bake", str(src), "-o", out, "--channels", "head.rq").stderr
    assert run_main("bake", str(src), "-o", out, "--scale", "0").returncode == 2
    assert run_main("bake", str(src), "-o", out, "--preset", "nope").returncode == 2
    assert "file not found" in run_main("bake", str(tmp_path / "none.csv"), "-o", out).stderr


def test_output_gets_the_usual_file_mode(tmp_path: Path) -> None:
    import os

    src, out = tmp_path / "horse.csv", tmp_path / "rider.csv"
    write_csv(src, horse_take(3))
    assert run_cli("bake", str(src), "-o", str(out)).returncode == 0
    mask = os.umask(0)
    os.umask(mask)
    assert out.stat().st_mode & 0o777 == 0o666 & ~mask


def test_timings_print_in_units_that_keep_three_figures() -> None:
    """A short take reads in k frames/s and milliseconds (it printed '0.00 M frames/s')."""
    from riderlive.bake import Timings

    assert str(Timings(1201, 0.004, 0.0011, 0.002)) == (
        "1,201 frames in 7.1 ms (169 k frames/s): read 4 ms, rules 1.1 ms, write 2 ms"
    )
    assert str(Timings(72_000_000, 1.2, 3.5, 4.1, 0.3)) == (
        "72,000,000 frames in 8.8 s (8.18 M frames/s): read 1.2 s, rules 3.5 s (smoothing 300 ms), write 4.1 s"
    )
    assert "(250 frames/s)" in str(Timings(250, 0.5, 0.25, 0.25))
    assert "(too fast to time)" in str(Timings(10, 0.0, 0.0, 0.0))


def test_the_saddle_columns_are_at_the_services_saddle_point_in_metres(tmp_path: Path) -> None:
    from riderlive.saddle import SaddlePoint, saddle_from_horse
    from riderlive.units import HORSE_LENGTHS

    horse = horse_take(20, seed=4)  # +-5 deg
    horse[:, list(HORSE_LENGTHS)] *= 0.02  # +-10 cm: a plausible horse in metres
    src, out = tmp_path / "h.csv", tmp_path / "r.csv"
    in_rig_units = horse.copy()
    in_rig_units[:, list(HORSE_LENGTHS)] *= 25.0  # the take in thesis rig units (--scale 1)
    write_csv(src, in_rig_units)
    service = tmp_path / "service.toml"
    service.write_text("[saddle]\nforward = 0.9\nup = 0.3\n")
    done = run_main("bake", str(src), "-o", str(out), "--scale", "1", "--saddle", "--config", str(service))
    assert done.returncode == 0, done.stderr
    header, values = read_csv(out)
    assert header[-6:] == ["saddle.tx", "saddle.ty", "saddle.tz", "saddle.rx", "saddle.ry", "saddle.rz"]
    point = SaddlePoint(forward=0.9, up=0.3)
    expected = np.array([saddle_from_horse(row, point) for row in horse])  # m, deg
    np.testing.assert_allclose(values[:, -6:], expected, atol=1e-9)
    default = np.array([saddle_from_horse(row) for row in horse])
    assert np.abs(default[:, :3] - expected[:, :3]).max() > 1e-3
