"""The output record's one layout: packing, named views, and the refusal of another layout."""

from __future__ import annotations

import pickle
from collections import Counter

import numpy as np
import orjson
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.channels import HORSE_NAMES, RIDER_NAMES, SADDLE_NAMES
from riderlive.channels import RIDER_PART_NAMES as PART_NAMES
from riderlive.realtime.record import LayoutMismatch, RecordLayout, RecordValues
from riderlive.realtime.saddle_input import GAITS, LOCKS
from riderlive.service.codecs import Subscription
from riderlive.service.config import TimecodeSection
from riderlive.service.poses import RecordPoses
from riderlive.service.rider_frames import encode_frame, saddle_estimate
from riderlive.service.timecodes import host_timecode

# The offsets every reader sliced by hand before the layout (``realtime/layout.py`` on main,
# 2026-11): the differential oracle. Records in the ring keep them, so a reader by name reads
# what the reader by offset read.
OLD_SEQ, OLD_ENGINE_T, OLD_SOURCE_T, OLD_DRIVER, OLD_PRODUCER, OLD_INPUT_RX, OLD_DONE, OLD_LATENESS = range(8)
OLD_SADDLE = 8
OLD_ESTIMATE = OLD_SADDLE + 6
OLD_HORSE = OLD_ESTIMATE + 5
OLD_RIDER = OLD_HORSE + len(HORSE_NAMES)
OLD_WIDTH = OLD_RIDER + len(RIDER_NAMES)
PHYSICS = tuple(f"tail_{i:02d}.{a}" for i in range(3) for a in ("rx", "ry", "tz"))

finite = st.floats(-1e6, 1e6, allow_nan=False)
codes = st.integers(-1, 2**31)


def old_pack(v: RecordValues) -> list[float]:
    """The record as the tick wrote it before the layout: its list literal, in concatenation order."""
    head = [float(v.seq), v.engine_t, v.source_t, float(v.driver), float(v.producer), v.input_rx, v.done, v.lateness]
    return [*head, *v.saddle, *v.estimate, *v.horse, *v.rider, *v.physics, *v.parts]


@st.composite
def records(draw: st.DrawFn) -> tuple[RecordLayout, RecordValues]:
    n = draw(st.integers(0, len(PHYSICS)))
    layout = RecordLayout(PHYSICS[:n], PART_NAMES)

    def run(width: int) -> tuple[float, ...]:
        return tuple(draw(st.lists(finite, min_size=width, max_size=width)))

    values = RecordValues(
        seq=draw(st.integers(0, 2**40)),
        engine_t=draw(finite),
        source_t=draw(finite),
        driver=draw(st.integers(0, 2)),
        producer=draw(codes),
        input_rx=draw(finite),
        done=draw(finite),
        lateness=draw(finite),
        saddle=run(len(SADDLE_NAMES)),
        estimate=(draw(st.sampled_from(range(len(LOCKS)))), draw(st.sampled_from(range(len(GAITS)))), *run(3)),
        horse=run(len(HORSE_NAMES)),
        rider=run(len(RIDER_NAMES)),
        physics=run(n),
        parts=run(len(PART_NAMES)),
    )
    return layout, values


@settings(deadline=None)  # a loaded host's first example (imports, caches) is slow; no timing asserted
@given(records())
def test_pack_then_unpack_gives_every_field_back(case: tuple[RecordLayout, RecordValues]) -> None:
    layout, values = case
    row = np.array(layout.pack_values(values))
    assert len(row) == layout.width
    assert layout.unpack(row) == values
    assert layout.pack_values(layout.unpack(row)) == row.tolist()


@settings(deadline=None)  # a loaded host's first example (imports, caches) is slow; no timing asserted
@given(records())
def test_the_layout_packs_what_the_old_tick_wrote_and_readers_read_the_old_offsets(
    case: tuple[RecordLayout, RecordValues],
) -> None:
    """Differential: the packed record is the old one slot for slot, and each named read is the
    old offset's read (the codec's JSON frame, the timecode, the saddle estimate, the poses)."""
    layout, values = case
    row = np.array(layout.pack_values(values))
    assert row.tolist() == old_pack(values)
    assert RecordLayout.seq.count(row) == int(row[OLD_SEQ]) and RecordLayout.driver.count(row) == int(row[OLD_DRIVER])
    assert RecordLayout.producer.count(row) == int(row[OLD_PRODUCER])
    for name, old in (
        ("engine_t", OLD_ENGINE_T),
        ("source_t", OLD_SOURCE_T),
        ("input_rx", OLD_INPUT_RX),
        ("done", OLD_DONE),
        ("lateness", OLD_LATENESS),
    ):
        assert layout.field(name).at(row) == row[old]
    np.testing.assert_array_equal(RecordLayout.saddle.of(row), row[OLD_SADDLE:OLD_ESTIMATE])
    np.testing.assert_array_equal(RecordLayout.estimate.of(row), row[OLD_ESTIMATE:OLD_HORSE])
    np.testing.assert_array_equal(RecordLayout.horse.of(row), row[OLD_HORSE:OLD_RIDER])
    np.testing.assert_array_equal(RecordLayout.rider.of(row), row[OLD_RIDER:OLD_WIDTH])
    np.testing.assert_array_equal(layout.published.of(row), row[OLD_RIDER:])
    np.testing.assert_array_equal(layout.parts.of(row), row[-len(PART_NAMES) :])
    # The service's recorder: the rider and the physics (old: OUTPUT_WIDTH + len(physics)).
    recorded = slice(RecordLayout.rider.start, layout.physics.stop)
    np.testing.assert_array_equal(row[recorded], row[OLD_RIDER : OLD_WIDTH + len(layout.physics_channels)])

    sub = Subscription(rider=tuple(range(len(layout.names))), horse=(0, 3), saddle=True)
    frame = orjson.loads(encode_frame(sub, row))
    assert frame["seq"] == int(row[OLD_SEQ]) and frame["t"] == row[OLD_ENGINE_T]
    assert frame["source_t"] == row[OLD_SOURCE_T]
    assert frame["values"] == row[OLD_RIDER:].tolist()
    assert frame["horse"] == [row[OLD_HORSE], row[OLD_HORSE + 3]]
    assert frame["saddle"] == row[OLD_SADDLE:OLD_ESTIMATE].tolist()


def test_readers_by_name_of_a_packed_record() -> None:
    """The timecode, the poses and the estimate read from a record the layout packed."""
    layout = RecordLayout(PHYSICS, PART_NAMES)
    values = RecordValues(
        seq=41,
        engine_t=2.5,
        source_t=2.25,
        driver=0,
        producer=-1,
        input_rx=-1.0,
        done=2.501,
        lateness=0.0002,
        saddle=(1.0, 2.0, 3.0, 4.0, 5.0, 6.0),
        estimate=(2.0, 1.0, 1.6, 0.25, 0.01),
        horse=tuple(0.0 for _ in HORSE_NAMES),
        rider=tuple(0.0 for _ in RIDER_NAMES),
        physics=tuple(float(i) for i in range(len(PHYSICS))),
        parts=tuple(0.0 for _ in PART_NAMES),
    )
    row = np.array(layout.pack_values(values))
    stamps = host_timecode(TimecodeSection(), 0.0, Counter())
    assert stamps.of_record(row) == stamps.at(2.5, 2.25, 0, -1)
    estimate = saddle_estimate(RecordLayout.estimate.of(row))
    assert estimate is not None and estimate["stride_hz"] == 1.6 and estimate["phase"] == 0.25
    poses = RecordPoses(25.0)
    assert poses.rider(row) is poses.rider(row), "solved once per seq"
    np.testing.assert_array_equal(layout.physics.of(row), np.arange(len(PHYSICS), dtype=float))


def test_a_field_of_the_wrong_length_is_refused_by_name() -> None:
    layout = RecordLayout(PHYSICS[:2], PART_NAMES)
    values = RecordValues(
        0, 0.0, 0.0, 0, -1, -1.0, 0.0, 0.0, (0.0,) * 6, (0.0,) * 5, (0.0,) * len(HORSE_NAMES),
        (0.0,) * len(RIDER_NAMES), (0.0,) * 3, (0.0,) * len(PART_NAMES),
    )  # fmt: skip
    with pytest.raises(ValueError, match="'physics' needs 2 values, got 3"):
        layout.pack_values(values)
    with pytest.raises(LayoutMismatch, match="a record of 3 slots"):
        layout.unpack(np.zeros(3))


def test_another_layout_is_refused_naming_both() -> None:
    web = RecordLayout(PHYSICS, PART_NAMES)
    tick = RecordLayout((), PART_NAMES)
    web.require_same(pickle.loads(pickle.dumps(web)), "the web process", "the tick")  # travels by pickle
    with pytest.raises(LayoutMismatch) as err:
        web.require_same(tick, "the web process's setup", "the tick")
    message = str(err.value)
    assert web.describe() in message and tick.describe() in message
    assert f"physics[{OLD_WIDTH}:{OLD_WIDTH + len(PHYSICS)}]" in message and "tail_00.rx" in message


def test_every_field_is_named_once_and_the_fields_tile_the_record() -> None:
    layout = RecordLayout(PHYSICS, PART_NAMES)
    stops = [0]
    for f in layout.fields:
        assert f.start == stops[-1], f"{f.name} starts where the one before stops"
        stops.append(f.stop)
        assert f.width == 1 or len(f.channels) == f.width
    assert stops[-1] == layout.width == OLD_WIDTH + len(PHYSICS) + len(PART_NAMES)
    assert len({f.name for f in layout.fields}) == len(layout.fields)
    assert layout.names == (*RIDER_NAMES, *PHYSICS, *PART_NAMES)
    with pytest.raises(KeyError, match="no record field 'tail'"):
        layout.field("tail")
