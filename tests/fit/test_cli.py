"""``riderlive fit`` end to end on files, and the bad inputs it must refuse with a clear message."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from riderlive.cli import main
from riderlive.framefile import FrameTable, read_frames, write_frames
from riderlive.frameunits import METRES, record_scale
from riderlive.rules.params import load_preset
from tests.fit.takes import horse_table, rider_table


def write_pair(tmp: Path, what: str, preset: str, seconds: float = 6.0, shift: float = 0.0) -> tuple[str, str]:
    horse, rider = tmp / f"{what}.csv", tmp / f"{what}_rider.csv"
    write_frames(str(horse), horse_table(what, seconds))
    record_scale(str(horse), METRES)
    r = rider_table(what, load_preset(preset), seconds)
    write_frames(str(rider), FrameTable(r.names, r.values, r.t + shift))
    return str(horse), str(rider)


def test_a_fitted_preset_loads_bakes_the_rider_back_and_carries_its_provenance(tmp_path: Path) -> None:
    takes = [*write_pair(tmp_path, "trot", "english"), *write_pair(tmp_path, "jump", "english")]
    out, report = tmp_path / "my_rider.toml", tmp_path / "fit.json"
    plot = tmp_path / "fit.png"
    assert main(["fit", *takes, "-o", str(out), "--report", str(report), "--plot", str(plot), "--quiet"]) == 0
    fitted = load_preset(out)
    assert fitted.name == "my_rider"
    data = json.loads(report.read_text())
    english = load_preset("english").flat()
    for p in data["parameters"]:
        if p["identified"]:
            assert p["value"] == pytest.approx(english[p["name"]], rel=0.01, abs=1e-3), p["name"]
            assert p["uncertainty"] is not None
        elif p["status"].startswith("not identified"):
            assert fitted.flat()[p["name"]] == load_preset("kuhnel2003").flat()[p["name"]]
    text = out.read_text()
    for take in data["takes"]:
        assert take["offset_s"] == 0.0
        assert f"sha256:{take['horse_sha256']}" in text and f"sha256:{take['rider_sha256']}" in text
        assert all(c["rms"] < 1e-9 for c in take["channels"])
    assert plot.stat().st_size > 10_000
    baked = tmp_path / "check.csv"
    assert main(["bake", takes[0], "--preset", str(out), "-o", str(baked)]) == 0
    np.testing.assert_allclose(read_frames(str(baked)).values, read_frames(takes[1]).values, atol=1e-6)


def test_a_clock_offset_is_found_and_applied(tmp_path: Path) -> None:
    horse, rider = write_pair(tmp_path, "canter", "child", seconds=6.0, shift=-0.2)
    report = tmp_path / "fit.json"
    assert main(["fit", horse, rider, "-o", str(tmp_path / "c.toml"), "--report", str(report), "--quiet"]) == 0
    assert json.loads(report.read_text())["takes"][0]["offset_s"] == pytest.approx(0.2, abs=1e-9)


def fails(capsys: pytest.CaptureFixture[str], args: list[str], *words: str) -> None:
    assert main(["fit", *args]) == 2
    err = capsys.readouterr().err
    for word in words:
        assert word in err, err


def test_bad_takes_are_refused_with_a_reason_and_no_preset(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "never.toml"
    horse, rider = write_pair(tmp_path, "trot", "english")
    late_horse, late_rider = write_pair(tmp_path, "walk", "english", shift=100.0)
    fails(capsys, [late_horse, late_rider, "-o", str(out)], "do not overlap")
    fails(capsys, [horse, "-o", str(out)], "pairs")
    fails(capsys, [rider, rider, "-o", str(out)], "not a horse take")
    fails(capsys, [horse, horse, "-o", str(out)], "not rider channels")
    # a horse in metres with nothing saying so
    bare = tmp_path / "bare.csv"
    write_frames(str(bare), horse_table("trot", 6.0))
    fails(capsys, [str(bare), rider, "-o", str(out)], "looks like metres", "--scale")
    # NaN in a take
    lines = Path(rider).read_text().splitlines()
    cells = lines[6].split(",")
    cells[1] = "nan"
    lines[6] = ",".join(cells)
    nan_rider = tmp_path / "nan_rider.csv"
    nan_rider.write_text("\n".join(lines) + "\n")
    fails(capsys, [horse, str(nan_rider), "-o", str(out)], "nan_rider.csv")
    # too short
    short_h, short_r = tmp_path / "short.csv", tmp_path / "short_rider.csv"
    h = read_frames(horse)
    write_frames(str(short_h), FrameTable(h.names, h.values[:60], h.t[:60]))
    record_scale(str(short_h), METRES)
    r = read_frames(rider)
    write_frames(str(short_r), FrameTable(r.names, r.values[:60], r.t[:60]))
    fails(capsys, [str(short_h), str(short_r), "-o", str(out)], "too short")
    assert not out.exists()


def test_a_rider_take_in_its_own_length_unit_is_converted(tmp_path: Path) -> None:
    """A rider in centimetres (its sidecar says so) beside a horse in metres fits as the same rider."""
    from riderlive.channels import Kind, lookup

    horse, rider = write_pair(tmp_path, "trot", "english")
    table = read_frames(rider)
    values = table.values.copy()
    for j, name in enumerate(table.names):
        if lookup(name).kind is Kind.TRANSLATION:
            values[:, j] *= 100.0
    in_cm = tmp_path / "trot_rider_cm.csv"
    write_frames(str(in_cm), FrameTable(table.names, values, table.t))
    record_scale(str(in_cm), METRES / 100.0)
    report = tmp_path / "fit.json"
    assert main(["fit", horse, str(in_cm), "-o", str(tmp_path / "cm.toml"), "--report", str(report), "--quiet"]) == 0
    data = json.loads(report.read_text())
    assert any("converted" in n for n in data["notes"])
    assert all(c["rms"] < 1e-9 for c in data["takes"][0]["channels"])
