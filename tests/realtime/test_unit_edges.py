"""Differential: the tick's unit conversions, moved to its edges, change no output.

The *old path* below is the tick's conversion code as it was before the conversions left
``TickCore`` (main at 32b40e3: ``TickCore.procedural_frame``'s gain, ``saddle_pose``'s
round trip through metres, ``RiderParts`` built with ``metres_per_unit``, ``frame_of``'s
``TickFrame.build``), kept here as the oracle. Over length scales 0.25..2500 and random
horse frames, what the tick publishes (the record's horse, rider, saddle and parts: the
wire, in the service unit) and what it hands the devices (the ``TickFrame``, metres) must
equal it to the bit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.channels import HORSE, HORSE_NAMES, Kind
from riderlive.horse import ProceduralHorse
from riderlive.realtime.core import Mode, TickCore, TickResult, Timing
from riderlive.realtime.frame import frame_of
from riderlive.rules import RiderModel
from riderlive.rules.parts import RiderParts
from riderlive.saddle import SaddlePoint, saddle_from_horse
from riderlive.saddle.pose import BEND_COLUMN, SCALAR, TRUNK_COLUMNS, saddle_from_trunk
from riderlive.tickframe import Flag, TickFrame

TIMING = Timing(delay=0.0, hold=10.0, blend_time=0.0, ease_time=0.0, param_blend=0.0)
LENGTH = tuple(c.kind is Kind.TRANSLATION for c in HORSE)


# -- the old path (the oracle) --------------------------------------------------------------


def old_saddle_pose(horse: Sequence[float], to_metres: float, point: SaddlePoint) -> list[float]:
    if to_metres == 1.0:
        return saddle_from_horse(horse, point)
    trunk = [horse[i] * to_metres if k < 3 else horse[i] for k, i in enumerate(TRUNK_COLUMNS)]
    out = saddle_from_trunk(trunk, horse[BEND_COLUMN], point, SCALAR)
    return [v / to_metres if k < 3 else v for k, v in enumerate(out)]


def old_procedural(horse: ProceduralHorse, now: float, scale: float) -> list[float]:
    frame = horse.sample(now)
    gain = 25.0 / scale
    if gain != 1.0:
        for i, is_length in enumerate(LENGTH):
            if is_length:
                frame[i] *= gain
    return frame


def old_outputs(model: RiderModel, horse: list[float], point: SaddlePoint) -> tuple[list[float], ...]:
    """Record fields (horse, rider, saddle, parts) of a first tick on ``horse``, as the old tick made them."""
    to_metres = model.scale / 25.0
    rider = model.evaluate(horse)
    parts = RiderParts(model.params, to_metres).evaluate(horse, rider)
    if not all(map(math.isfinite, parts)):
        parts = [0.0] * len(parts)
    return horse, rider, old_saddle_pose(horse, to_metres, point), parts


def old_frame(result: TickResult, t: float, scale: float) -> TickFrame:
    return TickFrame.build(
        3,
        t,
        t + 1.0,
        result.source_time,
        Flag.INPUT,
        result.rider,
        result.horse,
        result.saddle,
        result.estimate,
        scale / 25.0,
    )


# -- the strategies ---------------------------------------------------------------------------

scales = st.one_of(st.sampled_from([0.25, 1.0, 3.0, 25.0, 2500.0]), st.floats(0.25, 2500.0))
points = st.builds(SaddlePoint, forward=st.floats(0.0, 0.9), up=st.floats(-0.3, 0.5))


@st.composite
def horse_frames(draw: st.DrawFn, scale: float) -> list[float]:
    """A horse frame in the service unit of ``scale``: lengths within +-1.5 m, angles within +-40 deg."""
    k = scale / 25.0
    values = []
    for is_length in LENGTH:
        v = draw(st.floats(-1.5, 1.5) if is_length else st.floats(-40.0, 40.0))
        values.append(v / k if is_length else v)
    return values


@settings(max_examples=150)
@given(data=st.data(), scale=scales, point=points)
def test_a_driven_tick_publishes_and_hands_the_devices_what_the_old_path_did(
    data: st.DataObject, scale: float, point: SaddlePoint
) -> None:
    horse = data.draw(horse_frames(scale))
    model = RiderModel(scale=scale)
    core = TickCore(model, TIMING, ProceduralHorse(), Mode.INPUT, saddle_point=point)
    core.push_input(1, 0.5, 0.5, horse)
    result = core.step(0.5)
    want = old_outputs(model, horse, point)
    got = (result.horse, result.rider, result.saddle, result.parts or [0.0] * len(want[3]))
    for name, a, b in zip(("horse", "rider", "saddle", "parts"), got, want, strict=True):
        assert list(a) == list(b), f"record {name} at scale {scale}"
    assert frame_of(result, 3, 0.5, 1.5, scale / 25.0) == old_frame(result, 0.5, scale)


@settings(max_examples=60)
@given(scale=scales, now=st.floats(0.0, 600.0), point=points)
def test_a_procedural_tick_publishes_what_the_old_path_did(scale: float, now: float, point: SaddlePoint) -> None:
    model = RiderModel(scale=scale)
    core = TickCore(model, TIMING, ProceduralHorse("trot", 3.5, 1), Mode.PROCEDURAL, saddle_point=point)
    result = core.step(now)
    horse = old_procedural(ProceduralHorse("trot", 3.5, 1), now, scale)
    assert result.horse == horse
    assert result.saddle == old_saddle_pose(horse, scale / 25.0, point)
    assert len(horse) == len(HORSE_NAMES)
