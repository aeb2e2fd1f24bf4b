"""The tick's rider parts: of the published rider, neck-less streams, full reach counted."""

from __future__ import annotations

import numpy as np
import pytest

from riderlive.channels import HORSE_INDEX, HORSE_NAMES, RIDER_PART_NAMES
from riderlive.horse import ProceduralHorse
from riderlive.realtime.core import TickCore, Timing
from riderlive.rules import RiderModel
from riderlive.rules.params import load_preset
from riderlive.rules.parts import RiderParts

PARAMS = load_preset("kuhnel2003")
TIMING = Timing(delay=0.0, hold=10.0, blend_time=0.0)
SLIP = RIDER_PART_NAMES.index("reins.slip")


def core(scale: float = 25.0) -> TickCore:
    return TickCore(RiderModel(PARAMS, scale=scale), TIMING, ProceduralHorse("canter"))


def test_every_tick_carries_the_parts_of_what_it_publishes() -> None:
    c = core()
    parts = RiderParts(PARAMS)
    for t in np.arange(0.0, 1.0, 1 / 60):
        out = c.step(float(t))
        assert len(out.parts) == len(RIDER_PART_NAMES)
        assert out.parts == pytest.approx(parts.evaluate(out.horse, out.rider), abs=1e-15)
    assert c.full_reach == 0


def test_a_stream_without_neck_or_head_holds_them_at_rest() -> None:
    """Producers that never send the optional channels leave them 0: the reins of a neck at rest."""
    c = core()
    frame = [0.0] * len(HORSE_NAMES)
    frame[HORSE_INDEX["rearPivot.rz"]] = 4.0
    c.push_input(3, 0.0, 0.0, frame)
    out = c.step(0.01)
    with_neck = list(frame)
    with_neck[HORSE_INDEX["horseNeck.rz"]] = -20.0
    assert out.parts == pytest.approx(RiderParts(PARAMS).evaluate(frame, out.rider), abs=1e-15)
    assert out.parts != pytest.approx(RiderParts(PARAMS).evaluate(with_neck, out.rider), abs=1e-6)


def test_reins_beyond_reach_are_counted_each_tick() -> None:
    c = core(scale=2.5)  # another length unit: the parts convert to the skeletons' metres
    frame = [0.0] * len(HORSE_NAMES)
    frame[HORSE_INDEX["horseNeck.rz"]] = -70.0
    frame[HORSE_INDEX["horseHead.rz"]] = 60.0
    c.push_input(3, 0.0, 0.0, frame)
    outs = [c.step(t) for t in (0.01, 0.02, 0.03)]
    assert all(o.parts[SLIP] > 0.05 for o in outs)
    assert c.full_reach == 3


def test_a_non_finite_neck_falls_back_to_appendix_b_limbs() -> None:
    c = core()
    for k, bad in enumerate((float("nan"), float("inf"))):
        frame = [0.0] * len(HORSE_NAMES)
        frame[HORSE_INDEX["horseNeck.rz"]] = bad
        c.push_input(3, k * 0.1, k * 0.1, frame)
        out = c.step(k * 0.1 + 0.01)
        assert out.parts == [0.0] * len(RIDER_PART_NAMES)
        assert all(np.isfinite(out.rider))
