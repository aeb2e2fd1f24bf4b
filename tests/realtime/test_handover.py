"""The hand-over of the tick's state (realtime/handover.py): a fresh core restored from a
snapshot and the input ring goes on exactly as the one it replaces."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest

from riderlive.channels import HORSE_INDEX, HORSE_NAMES
from riderlive.horse import ProceduralHorse
from riderlive.realtime import handover
from riderlive.realtime import layout as L
from riderlive.realtime import phase_lock as phase
from riderlive.realtime.core import Driver, Mode, TickCore, Timing
from riderlive.realtime.shm import SharedRing
from riderlive.rules import RiderModel
from riderlive.rules.params import FollowThrough, RuleParams, Smoothing

TIMING = Timing(delay=0.01, hold=0.25, ease_time=0.5, blend_time=0.3, param_blend=0.5)
PARAMS = RuleParams().model_copy(
    update={"smoothing": Smoothing(time_constant=0.05), "follow_through": FollowThrough(frequency=3.0)}
)
PERIOD = 0.01


def model() -> RiderModel:
    return RiderModel(params=PARAMS, scale=25.0)


def horse_frame(t: float) -> list[float]:
    f = [0.0] * len(HORSE_NAMES)
    f[HORSE_INDEX["rearPivot.rz"]] = 4.0 * math.sin(2 * math.pi * 1.7 * t)
    f[HORSE_INDEX["rearPivot.ty"]] = 0.3 * math.sin(2 * math.pi * 3.4 * t)
    f[HORSE_INDEX["rfHoof.ty"]] = 0.2
    return f


def push(ring: SharedRing, producer: int, t: float, received: float) -> None:
    ring.write(L.InputRecord(producer, t, received, list(horse_frame(t))).row())


def tick(core: TickCore, ring: SharedRing, now: float) -> list[float]:
    """What ``TickLoop.run`` does with the ring and the core each tick."""
    for record in ring.read_new():
        core.push_record(L.InputRecord.of(record))
    return core.step(now).rider


def same(a: object, b: object) -> bool:
    """Equal to the bit (NumPy arrays inside: compared by their pickles)."""
    return pickle.dumps(a) == pickle.dumps(b)


@pytest.fixture
def ring() -> SharedRing:
    ring = SharedRing(L.INPUT_CAPACITY, L.INPUT_WIDTH)
    yield ring
    ring.close()


def running_core(ring: SharedRing, ticks: int) -> tuple[TickCore, float]:
    """A core that has been driven: a producer that left, then producer 7 at 100 Hz (its
    clock 1000 s ahead), a parameter change mid-way; returns it and the last tick's time."""
    core = TickCore(model(), TIMING, ProceduralHorse("trot", None, 3), Mode.INPUT)
    now = 0.0
    for n in range(ticks):
        now = n * PERIOD
        if n < 50:
            push(ring, 3, now, now + 0.002)
        elif n == 50:
            core.producer_gone(3)
        else:
            push(ring, 7, 1000.0 + now, now + 0.003)
        if n == 150:
            core.set_model(RiderModel(params=PARAMS.model_copy(update={"name": "changed"}), scale=25.0))
        tick(core, ring, now)
    return core, now


def snapshot_of(core: TickCore, ring: SharedRing, now: float) -> handover.TickSnapshot:
    return handover.TickSnapshot(
        handover.VERSION, 1, round(now / PERIOD), 0.0, now, 0, 0, ring.read_next,
        handover.capture_core(core), core.horse, phase.start(0.0), ("an event",),
        handover.Settings("trot", None, None, Mode.INPUT),
    )  # fmt: skip


def test_a_restored_core_goes_on_exactly_as_the_original(ring: SharedRing) -> None:
    core, now = running_core(ring, 160)  # in the middle of the parameter blend, filters running
    assert core.driver is Driver.INPUT and core.producer == 7 and core._param_delta is not None
    snapshot = handover.decode(handover.encode(snapshot_of(core, ring, now)))
    assert snapshot is not None
    spare_ring = SharedRing(0, 0, name=ring.name)  # the spare attaches to the same ring
    try:
        spare = TickCore(RiderModel(params=PARAMS.model_copy(update={"name": "changed"}), scale=25.0), TIMING,
                         ProceduralHorse("trot", None, 3), Mode.INPUT)  # fmt: skip
        replayed = handover.restore(spare, spare_ring, snapshot, now, blend_time=0.0)
        assert replayed == min(handover.REPLAY, ring.read_next) == 159, "every record before the read position"
        assert spare_ring.read_next == ring.read_next
        assert list(spare.resampler.times) == list(core.resampler.times)
        assert spare.resampler.offset == core.resampler.offset
        assert same(handover.capture_core(spare), handover.capture_core(core))
        # Frames the dead tick never read are read by the spare, once.
        for n in range(161, 260):
            t = n * PERIOD
            push(ring, 7, 1000.0 + t, t + 0.003)
            a, b = tick(core, ring, t), tick(spare, spare_ring, t)
            np.testing.assert_allclose(b, a, rtol=0, atol=1e-12, err_msg=f"tick {n}")
    finally:
        spare_ring.close()


def test_the_takeover_blends_from_the_last_frame_within_one_ticks_motion(ring: SharedRing) -> None:
    core, now = running_core(ring, 300)
    snapshot = snapshot_of(core, ring, now)
    last = np.array(core.last_rider)
    gap = 0.05  # 50 ms without a tick: the horse moved on by 5 ticks
    for n in range(1, 12):
        t = now + n * PERIOD
        push(ring, 7, 1000.0 + t, t + 0.003)
    # The slew: the largest per-tick change of each channel had the tick gone on.
    probe_ring = SharedRing(0, 0, name=ring.name)
    spare_ring = SharedRing(0, 0, name=ring.name)
    try:
        probe_ring.read_next = ring.read_next
        previous, steps = last, []
        for n in range(1, 12):
            out = np.array(tick(core, probe_ring, now + n * PERIOD))
            steps.append(np.abs(out - previous))
            previous = out
        slew = np.max(steps, axis=0)
        spare = TickCore(RiderModel(params=PARAMS.model_copy(update={"name": "changed"}), scale=25.0), TIMING,
                         ProceduralHorse("trot", None, 3), Mode.INPUT)  # fmt: skip
        handover.restore(spare, spare_ring, snapshot, now + gap, TIMING.blend_time)
        previous = last
        for n in range(5, 12):  # the spare's ticks, on the same grid
            out = np.array(tick(spare, spare_ring, now + n * PERIOD))
            assert np.all(np.abs(out - previous) <= slew + 1e-9), (n, float((np.abs(out - previous) - slew).max()))
            previous = out
        without = TickCore(model(), TIMING, ProceduralHorse("trot", None, 3), Mode.INPUT)
        restart = SharedRing(0, 0, name=ring.name)
        restart.read_next = spare_ring.read_next - 7
        jump = np.abs(np.array(tick(without, restart, now + gap)) - last)
        restart.close()
        assert np.any(jump > slew), "a restart without the hand-over would jump (the test can fail)"
    finally:
        probe_ring.close()
        spare_ring.close()


def test_every_core_attribute_is_handed_over_or_rebuilt() -> None:
    """A new TickCore attribute must be placed: handed over (``CORE_FIELDS``) or rebuilt (``CORE_REBUILT``)."""
    core = TickCore(model(), TIMING, ProceduralHorse(), Mode.INPUT)
    placed = set(handover.CORE_FIELDS.values()) | handover.CORE_REBUILT
    assert set(vars(core)) == placed, set(vars(core)) ^ placed


def test_settings_changed_while_no_tick_ran_win_over_the_snapshot(ring: SharedRing) -> None:
    core, now = running_core(ring, 60)
    snapshot = snapshot_of(core, ring, now)
    same_settings = TickCore(model(), TIMING, ProceduralHorse("trot", None, 3), Mode.INPUT)
    handover.restore(same_settings, SharedRing(0, 0, name=ring.name), snapshot, now, 0.0)
    assert same_settings.horse is snapshot.horse and same_settings.mode is Mode.INPUT
    walk = ProceduralHorse("walk", None, 3)
    changed = TickCore(model(), TIMING, walk, Mode.PROCEDURAL)
    settings = handover.Settings("walk", None, None, Mode.PROCEDURAL)
    handover.restore(changed, SharedRing(0, 0, name=ring.name), snapshot, now, 0.0, settings=settings)
    assert changed.horse is walk, "the horse as the new settings built it"
    assert changed.mode is Mode.PROCEDURAL, "the mode chosen while the tick was down"


def test_a_snapshot_of_another_version_or_none_is_ignored(ring: SharedRing) -> None:
    core, now = running_core(ring, 60)
    snapshot = snapshot_of(core, ring, now)
    decoded = handover.decode(handover.encode(snapshot))
    assert decoded is not None
    assert (decoded.tick, decoded.input_next, decoded.events) == (59, 59, ("an event",))
    assert decoded.settings == snapshot.settings
    assert decoded.core.last_rider == snapshot.core.last_rider and decoded.core.gone == (3,)
    assert decoded.core.damper is not None and snapshot.core.damper is not None
    np.testing.assert_array_equal(decoded.core.damper.value, snapshot.core.damper.value)
    older = handover.encode(handover.TickSnapshot(**{**vars(snapshot), "version": handover.VERSION - 1}))
    assert handover.decode(older) is None
    assert handover.decode(None) is None and handover.decode(b"") is None and handover.decode(b"\x80junk") is None
