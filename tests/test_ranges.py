"""Plausible channel ranges: lookup, units, and that no horse we make falls outside them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from riderlive.channels import HORSE_NAMES, RIDER_NAMES, Kind
from riderlive.horse import DEFAULT_SCALE, GAITS, generate, generate_gait
from riderlive.horse.script import load_script
from riderlive.ranges import DEFAULT_RANGES, KIND_DEFAULTS, Ranges, kind_of_name
from riderlive.rules import RiderModel, load_preset
from riderlive.service.config import ServiceConfig

SHOTS = sorted((Path(__file__).resolve().parents[1] / "config" / "shots").glob("*.toml"))


def test_limits_are_in_the_service_unit() -> None:
    """Lengths by ``units.metres_per_unit`` (a unit of L/25 m), angles as they are."""
    assert DEFAULT_RANGES.limits(["lfHoof.ty"], DEFAULT_SCALE) == ([-5.0], [5.0])
    lows, highs = DEFAULT_RANGES.limits(["lfHoof.ty", "rearPivot.rz"], 0.25)  # centimetres
    assert lows == pytest.approx([-500.0, DEFAULT_RANGES.of("rearPivot.rz")[0]], rel=1e-12)
    assert highs == pytest.approx([500.0, DEFAULT_RANGES.of("rearPivot.rz")[1]], rel=1e-12)


def test_lookup_order_name_pattern_kind() -> None:
    assert DEFAULT_RANGES.of("lfHoof.ty") == (-5.0, 5.0), "pattern *Hoof.t*"
    assert DEFAULT_RANGES.of("root.ry") == (-1e6, 1e6), "headings accumulate turns"
    assert DEFAULT_RANGES.of("lower_back.rz") == KIND_DEFAULTS[Kind.ROTATION]
    assert DEFAULT_RANGES.of("hair.up") == KIND_DEFAULTS[Kind.ATTRIBUTE]
    # A channel another module adds later gets its kind's range without being listed.
    assert kind_of_name("neck.rx") is Kind.ROTATION and DEFAULT_RANGES.of("neck.rx") == (-360.0, 360.0)
    assert DEFAULT_RANGES.of("neck.tx") == KIND_DEFAULTS[Kind.TRANSLATION]
    # The saddle input's: its point moves under 1.5 m and pitches under 90 deg from standing.
    assert DEFAULT_RANGES.of("saddle.ty") == (-1.5, 1.5) and DEFAULT_RANGES.of("saddle.rx") == (-90.0, 90.0)
    custom = Ranges(overrides={"lfHoof.ty": (0.0, 1.0), "saddle.*": (-1.0, 1.0)})
    assert custom.of("lfHoof.ty") == (0.0, 1.0) and custom.of("rfHoof.ty") == (-5.0, 5.0)
    assert custom.of("saddle.rz") == (-1.0, 1.0)
    with pytest.raises(ValueError, match="low < high"):
        Ranges(overrides={"x.ty": (1.0, -1.0)})


def test_limits_are_in_the_service_length_unit() -> None:
    low, high = DEFAULT_RANGES.limits(["lfHoof.ty", "rearPivot.rz"], 25.0)
    assert (low, high) == ([-5.0, -90.0], [5.0, 90.0]), "metres at length_scale 25"
    low, high = DEFAULT_RANGES.limits(["lfHoof.ty", "rearPivot.rz"], 1.0)
    assert (low, high) == ([-125.0, -90.0], [125.0, 90.0]), "thesis rig units at length_scale 1"


def test_config_overrides_and_refuses_unknown_names() -> None:
    config = ServiceConfig.model_validate({"ranges": {"channels": {"root.t*": [-10, 10]}, "rotation": [-180, 180]}})
    ranges = config.ranges.ranges()
    assert ranges.of("root.tx") == (-10.0, 10.0) and ranges.of("head.rz") == (-180.0, 180.0)
    with pytest.raises(ValueError, match="unknown channel"):
        ServiceConfig.model_validate({"ranges": {"channels": {"lfhoof.ty": [0, 1]}}})
    with pytest.raises(ValueError):
        ServiceConfig.model_validate({"ranges": {"length": [5, 1]}})


@pytest.mark.parametrize("source", [*GAITS, *(p.stem for p in SHOTS)])
def test_every_procedural_horse_and_its_rider_are_inside_the_ranges(source: str) -> None:
    shot = SHOTS[0].parent / f"{source}.toml"
    table = generate_gait(source, 12.0) if source in GAITS else generate(load_script(shot))
    horse = np.zeros((len(table), len(HORSE_NAMES)))
    for j, name in enumerate(table.names):
        horse[:, HORSE_NAMES.index(name)] = table.values[:, j]
    low, high = (np.array(b) for b in DEFAULT_RANGES.limits(HORSE_NAMES, DEFAULT_SCALE))
    assert np.all(horse >= low) and np.all(horse <= high), source
    for preset in ("kuhnel2003", "child", "english", "kuhnel2003_literal"):
        rider = RiderModel(params=load_preset(preset), scale=DEFAULT_SCALE).evaluate_batch(horse)
        low, high = (np.array(b) for b in DEFAULT_RANGES.limits(RIDER_NAMES, DEFAULT_SCALE))
        assert np.all(rider >= low) and np.all(rider <= high), (source, preset)
