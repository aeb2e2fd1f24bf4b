"""The tick's typed frame: metres and degrees, frozen, built once; parts and their check."""

from __future__ import annotations

import dataclasses
import math

import pytest

from riderlive.channels import HORSE, HORSE_INDEX, RIDER, RIDER_INDEX
from riderlive.realtime.core import Driver, TickResult
from riderlive.realtime.frame import frame_of
from riderlive.tickframe import (
    ALWAYS,
    Estimate,
    Flag,
    MissingPart,
    Part,
    TickFrame,
    check_parts,
    computed_parts,
    parse_parts,
)


def result(estimate: tuple[float, ...] = (math.nan,) * 5, driver: Driver = Driver.INPUT) -> TickResult:
    horse = [0.0] * len(HORSE)
    horse[HORSE_INDEX["rearPivot.ty"]] = 2.5  # service units
    horse[HORSE_INDEX["rearPivot.rz"]] = 4.0  # degrees
    rider = [0.0] * len(RIDER)
    rider[RIDER_INDEX["cog.ty"]] = -0.5
    rider[RIDER_INDEX["lower_back.rz"]] = 7.0
    saddle = [0.1, 0.2, 0.3, 1.0, 2.0, 3.0]
    return TickResult(driver, 12.0, 3, horse, rider, saddle, estimate)


def test_the_frame_is_in_metres_and_degrees_whatever_the_service_unit() -> None:
    # a service in centimetres: length_scale 0.25 (rig units per cm), 0.01 m per unit
    frame = frame_of(result(), tick=7, t=1.5, at=100.25, metres_per_unit=0.01)
    assert frame.horse[HORSE_INDEX["rearPivot.ty"]] == pytest.approx(0.025)
    assert frame.horse[HORSE_INDEX["rearPivot.rz"]] == 4.0  # angles never scale
    assert frame.rider[RIDER_INDEX["cog.ty"]] == pytest.approx(-0.005)
    assert frame.rider[RIDER_INDEX["lower_back.rz"]] == 7.0
    assert frame.saddle == pytest.approx((0.001, 0.002, 0.003, 1.0, 2.0, 3.0))
    assert (frame.tick, frame.t, frame.at, frame.source_time) == (7, 1.5, 100.25, 12.0)
    assert frame.flags == Flag.INPUT and frame.estimate is None
    assert len(frame.horse) == len(HORSE) and len(frame.rider) == len(RIDER)


def test_the_frame_is_frozen() -> None:
    frame = frame_of(result(), 0, 0.0, 0.0, 1.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        frame.saddle = (0.0,) * 6  # type: ignore[misc]
    assert isinstance(frame.horse, tuple) and isinstance(frame.rider, tuple)


def test_a_saddle_driven_tick_carries_its_estimate_and_a_held_one_says_so() -> None:
    frame = frame_of(result((3.0, 1.0, 1.6, 0.25, 0.004)), 0, 0.0, 0.0, 1.0, held=True)
    assert frame.flags == Flag.INPUT | Flag.SADDLE_INPUT | Flag.HELD
    assert frame.estimate == Estimate(lock=3, gait=1, stride_hz=1.6, phase=0.25, age=0.004)
    assert frame.wanting(frozenset({Part.ESTIMATE})) == ()
    searching = frame_of(result((2.0, math.nan, 0.0, 0.0, 0.1)), 0, 0.0, 0.0, 1.0)
    assert searching.estimate is not None and searching.estimate.gait == -1
    procedural = frame_of(result(driver=Driver.PROCEDURAL), 0, 0.0, 0.0, 1.0)
    assert procedural.flags == Flag.PROCEDURAL and procedural.wanting(frozenset({Part.ESTIMATE})) == (Part.ESTIMATE,)


def test_a_part_the_tick_does_not_compute_is_refused_naming_device_and_part() -> None:
    assert computed_parts(saddle_input=False) == ALWAYS == {Part.RIDER, Part.HORSE, Part.SADDLE}
    assert computed_parts(saddle_input=True) == ALWAYS | {Part.ESTIMATE}
    check_parts("bench3", [Part.RIDER], computed_parts(False))
    with pytest.raises(MissingPart) as err:
        check_parts("gyro_seat", [Part.SADDLE, Part.ESTIMATE], computed_parts(False))
    assert err.value.device == "gyro_seat" and err.value.part is Part.ESTIMATE
    assert "'gyro_seat'" in str(err.value) and "'estimate'" in str(err.value) and "saddle stream" in str(err.value)
    assert isinstance(err.value, ValueError)  # `riderlive serve` answers it as a configuration error (exit 2)


def test_parts_by_name() -> None:
    assert parse_parts(["saddle", "rider"]) == {Part.SADDLE, Part.RIDER}
    with pytest.raises(ValueError, match=r"'wheels'.*known: rider, horse, saddle, estimate"):
        parse_parts(["wheels"])


def test_a_rider_only_frame_leaves_the_other_parts_empty() -> None:
    frame = TickFrame.build(1, 0.0, 0.0, 0.0, Flag.PROCEDURAL, [1.0] * len(RIDER))
    assert frame.horse == () and frame.saddle == () and frame.estimate is None
