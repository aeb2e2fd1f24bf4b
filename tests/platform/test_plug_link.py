"""The platform plug's edge to its link (riderlive/platform/plug_link.py): counts, CONFIG values, errors."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.devices.lifecycle import Mismatch, NoReply, PortBusy, PortLost, Rejected
from riderlive.platform import link
from riderlive.platform.link_vocab import ConfigKey, FrameType, LinkState, Reason
from riderlive.platform.mechanism.config import PLATFORM_DIR
from riderlive.platform.mechanism.pipeline import PlatformModel
from riderlive.platform.plug_link import config_values, lifecycle_errors, position_units, target_counts
from riderlive.platform.serial_link import CommandRefused, NoAnswer, VersionMismatch
from riderlive.platform.serial_link import PortBusy as LinkBusy
from riderlive.platform.serial_link import PortLost as LinkLost

PLATFORMS = sorted(p.stem for p in PLATFORM_DIR.glob("*.toml"))


def model(name: str) -> PlatformModel:
    return PlatformModel.load(PLATFORM_DIR / f"{name}.toml")


def test_positions_to_counts_by_hand() -> None:
    assert position_units(model("stewart_compact")) == 1000.0  # m of stroke -> mm
    assert position_units(model("stewart_rotary")) == 1.0  # deg of crank
    assert target_counts([0.1, 0.0505, 0.0], 1000.0) == (10000, 5050, 0)  # 0.01 mm each
    assert target_counts(np.array([0.1, 0.0505, 0.0]), 1000.0) == (10000, 5050, 0)
    assert target_counts([12.34, -45.0], 1.0) == (1234, -4500)  # 0.01 deg each
    with pytest.raises(ValueError, match="outside"):
        target_counts([0.33], 1000.0)  # 330 mm: beyond the link's +-327.67
    with pytest.raises(ValueError):
        target_counts([math.nan], 1000.0)


@settings(deadline=None)
@given(st.lists(st.floats(-0.3, 0.3), min_size=1, max_size=8))
def test_counts_are_the_nearest_hundredth_of_a_millimetre(positions: list[float]) -> None:
    counts = target_counts(positions, 1000.0)
    assert counts == target_counts(np.array(positions), 1000.0)
    for q, c in zip(positions, counts, strict=True):
        assert abs(c / 1e5 - q) <= 0.5e-5 + 1e-12


@pytest.mark.parametrize("name", PLATFORMS)
def test_config_values_tighten_inward(name: str) -> None:
    m = model(name)
    g = m.geometry
    units = position_units(m)
    scale = units * link.COUNTS_PER_UNIT
    values = config_values(m, units, 200)
    assert values[0] == (ConfigKey.HEARTBEAT_TIMEOUT_MS, 0, 200)
    assert len(values) == 1 + 4 * g.legs
    for key, i, value in values[1:]:
        if key is ConfigKey.SOFT_MIN:  # rounded inward: never below the file's limit, within a count
            assert g.lower[i] * scale - 1e-6 <= value < g.lower[i] * scale + 1
        elif key is ConfigKey.SOFT_MAX:
            assert g.upper[i] * scale - 1 < value <= g.upper[i] * scale + 1e-6
        elif key is ConfigKey.VELOCITY_LIMIT:  # rounded down: never faster than the file
            assert value == math.floor(g.max_speed[i] * scale)
        else:
            assert key is ConfigKey.ACCELERATION_LIMIT and value == math.floor(g.max_accel[i] * scale)


def _refused() -> CommandRefused:
    status = link.Status(ack_seq=1, ack_type=FrameType.ARM, result=Reason.LATCHED, state=LinkState.FAULT, faults=0)
    return CommandRefused(link.Arm("p"), status)


@pytest.mark.parametrize(
    ("raised", "expected"),
    [
        (LinkLost("/dev/x vanished"), PortLost),
        (LinkBusy("/dev/x is held"), PortBusy),
        (NoAnswer("no answer"), NoReply),
        (VersionMismatch("/dev/x", 9), Mismatch),
        (_refused(), Rejected),
    ],
)
def test_the_link_errors_become_the_lifecycle_s(raised: Exception, expected: type[Exception]) -> None:
    counters: Counter[str] = Counter()
    with pytest.raises(expected) as caught, lifecycle_errors(counters):
        raise raised
    assert caught.value.__cause__ is raised
    assert counters["port_lost"] == (1 if isinstance(raised, LinkLost) else 0)


def test_other_errors_pass_unchanged() -> None:
    counters: Counter[str] = Counter()
    with pytest.raises(KeyError), lifecycle_errors(counters):
        raise KeyError("not the link's")
    assert not counters
