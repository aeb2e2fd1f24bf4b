"""``riderlive rig``: checks a map, prints its wire budget, drives it on the emulator."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from riderlive.cli import main
from riderlive.dynamixel.emulator import EmulatedBus
from riderlive.dynamixel.rig_cli import drive
from riderlive.dynamixel.tables import Item
from tests.dynamixel.rig_harness import servo_setups, short_rig


def test_check_prints_map_and_budget(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["rig", "full_rider"]) == 0
    out = capsys.readouterr().out
    assert "24 servos" in out and "2.60 ms" in out and "385 ticks/s" in out
    assert "seat_lift" in out and "cog.ty" in out


def test_bad_map_names_the_key(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('[servos.a]\nid = 1\nmodel = "XL330-M288"\nchannel = "nope.rz"\n')
    assert main(["rig", str(bad)]) == 2
    out = capsys.readouterr().out
    assert f"{bad}: servos.a.channel: unknown rider channel 'nope.rz'" in out


def test_drive_runs_the_lifecycle(bus_factory: Callable[..., EmulatedBus], capsys: pytest.CaptureFixture[str]) -> None:
    rig = short_rig("bench3")
    emu = bus_factory(servo_setups(rig), baud=rig.bus.baud)
    assert drive(rig.with_port(emu.port), 1.0, "walk") == 0
    out = capsys.readouterr().out
    for step in ("checking -> configuring", "soft_start -> running", "closed; fault: none"):
        assert step in out
    emu.settle()
    assert all(emu.read_item(i, Item.TORQUE_ENABLE) == 0 for i in (1, 2, 3))
