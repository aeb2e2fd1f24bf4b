"""Helpers to build horse frames by channel name."""

from __future__ import annotations

import pytest

from riderlive.channels import HORSE_INDEX, HORSE_NAMES, RIDER_INDEX
from riderlive.rules.engine import RiderModel
from riderlive.rules.params import load_preset


def horse_frame(**values: float) -> list[float]:
    """A horse frame with the named channels set (``lfHoof_tx=1.0``), the rest zero."""
    frame = [0.0] * len(HORSE_NAMES)
    for key, value in values.items():
        frame[HORSE_INDEX[key.replace("_", ".", 1) if "." not in key else key]] = value
    return frame


def rider(values: list[float], name: str) -> float:
    return values[RIDER_INDEX[name]]


@pytest.fixture(scope="session")
def thesis() -> RiderModel:
    """Appendix B with the chosen readings, alone: the ``[jump]`` layer (on in the preset, a layer on
    top of the rules over a fence) is off here; ``test_jump.py`` tests it and that it leaves gaits alone."""
    return RiderModel(params=load_preset("kuhnel2003").with_values({"jump.weight": 0.0}))


@pytest.fixture(scope="session")
def literal() -> RiderModel:
    return RiderModel(params=load_preset("kuhnel2003_literal"))
