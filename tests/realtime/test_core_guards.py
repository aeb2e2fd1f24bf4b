"""TickCore's guarantees: bounded, finite outputs; stateful stages that heal; parameter blends."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.channels import HORSE_INDEX, HORSE_NAMES, RIDER_INDEX, RIDER_NAMES
from riderlive.horse import ProceduralHorse
from riderlive.ranges import DEFAULT_RANGES
from riderlive.realtime.core import Driver, Mode, TickCore, Timing
from riderlive.rules import RiderModel, load_preset

SMOOTH = load_preset("kuhnel2003").with_values({"smoothing.time_constant": 0.05})
BOUNDS = DEFAULT_RANGES.limits(RIDER_NAMES, 25.0)
TIMING = Timing(delay=0.0, hold=1.0, ease_time=0.5, blend_time=0.2, param_blend=0.5)


def frame(rz: float, tx: float = 0.0) -> list[float]:
    f = [0.0] * len(HORSE_NAMES)
    f[HORSE_INDEX["rearPivot.rz"]] = rz
    f[HORSE_INDEX["lfHoof.tx"]] = tx
    f[HORSE_INDEX["rfHoof.ty"]] = 0.2
    return f


def feed(core: TickCore, rz, start: float, stop: float, dt: float = 0.005, tx=lambda t: 0.0) -> list:
    out = []
    for t in np.arange(start, stop, dt):
        core.push_input(1, float(t), float(t), frame(rz(t), tx(t)))
        out.append(core.step(float(t)))
    return out


def test_one_huge_frame_with_smoothing_on_never_freezes_the_rider() -> None:
    """The reported bug: one huge frame left the filter non-finite and the rider frozen for good.

    (1e308 m overflows to inf in rig units: that is a non-finite rules output, which
    touches no state; 1e305 m is finite there and overflows the filter.)"""
    for bounds in (BOUNDS, None):
        core = TickCore(RiderModel(params=SMOOTH, scale=25.0), TIMING, ProceduralHorse(), bounds=bounds)
        feed(core, lambda t: 3.0 * math.sin(6 * t), 0.0, 0.5)
        huge = frame(0.0, 1e305)
        core.push_input(1, 0.5, 0.5, huge)
        core.step(0.5)
        after = feed(core, lambda t: 3.0 * math.sin(6 * t), 0.505, 2.5)
        riders = np.array([r.rider for r in after])
        assert np.isfinite(riders).all()
        assert np.all(np.abs(np.diff(riders[-50:, RIDER_INDEX["lower_back.rz"]])) > 0), "still moving"
        reference = TickCore(RiderModel(params=SMOOTH, scale=25.0), TIMING, ProceduralHorse(), bounds=bounds)
        settled = feed(reference, lambda t: 3.0 * math.sin(6 * t), 0.0, 2.5)
        np.testing.assert_allclose(riders[-1], settled[-1].rider, atol=1e-6, err_msg="back on the input's track")
        if bounds is None:
            assert core.resets >= 1 and len(core.faults) == 1, "reset, reported once"
            assert "smoothing" in core.faults[0]
        else:
            assert core.resets == 0 and core.clamped > 0, "clamped before it reached the filter"


def test_a_reset_eases_from_neutral() -> None:
    core = TickCore(RiderModel(params=SMOOTH, scale=25.0), TIMING, ProceduralHorse())
    feed(core, lambda t: 4.0, 0.0, 0.5)
    core.push_input(1, 0.5, 0.5, frame(0.0, 1e305))
    core.step(0.5)
    first = feed(core, lambda t: 4.0, 0.505, 0.509)[0]
    neutral = np.array(core.neutral_rider)
    assert np.abs(np.array(first.rider) - neutral).max() < 1e-9, "starts from neutral"
    later = feed(core, lambda t: 4.0, 0.51, 1.2)
    target = np.array(RiderModel(params=SMOOTH, scale=25.0).evaluate(frame(4.0)))
    distances = [np.abs(np.array(r.rider) - target).max() for r in later]
    assert distances[-1] < 1e-3 * distances[0]
    assert all(b <= a + 1e-9 for a, b in zip(distances, distances[1:])), "eases monotonically"


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(allow_nan=False, allow_infinity=False, width=64), min_size=1, max_size=30))
def test_outputs_stay_within_their_ranges_whatever_the_horse(values: list[float]) -> None:
    core = TickCore(RiderModel(params=SMOOTH, scale=25.0), TIMING, ProceduralHorse(), bounds=BOUNDS)
    low, high = np.array(BOUNDS[0]), np.array(BOUNDS[1])
    for i, v in enumerate(values):
        f = [v] * len(HORSE_NAMES)
        core.push_input(1, i * 0.01, i * 0.01, f)
        rider = np.array(core.step(i * 0.01).rider)
        if np.isfinite(rider).all():
            assert np.all(rider >= low) and np.all(rider <= high)
        else:  # a non-finite rules output: no state touched, the tick loop repeats its last good frame
            assert core.last_rider is None or np.isfinite(core.last_rider).all()


def test_a_parameter_change_blends_on_the_moving_horse() -> None:
    old = RiderModel(params=load_preset("kuhnel2003"), scale=25.0)
    new = RiderModel(params=load_preset("child"), scale=25.0)
    core = TickCore(old, TIMING, ProceduralHorse(), mode=Mode.PROCEDURAL)
    for t in np.arange(0.0, 0.5, 0.005):
        core.step(float(t))
    core.set_model(new)
    t0 = 0.5
    first = core.step(t0)
    np.testing.assert_allclose(first.rider, old.evaluate(first.horse), atol=1e-12, err_msg="no jump at the change")
    delta = np.subtract(old.evaluate(first.horse), new.evaluate(first.horse))
    assert np.abs(delta).max() > 1.0
    for t in np.arange(t0 + 0.005, t0 + 0.7, 0.005):
        result = core.step(float(t))
        x = min((t - t0) / TIMING.param_blend, 1.0)
        fade = 1.0 - x * x * (3.0 - 2.0 * x)
        np.testing.assert_allclose(result.rider, np.add(new.evaluate(result.horse), delta * fade), atol=1e-12)


def test_changes_in_quick_succession_stay_continuous() -> None:
    """Four changes within 0.3 s: each tick moves at most the motion's own step plus the fades' slopes."""
    presets = [RiderModel(params=load_preset(name), scale=25.0) for name in ("kuhnel2003", "child", "english")]
    changes = {100: 1, 130: 2, 131: 0, 160: 1}
    times = np.arange(0.0, 2.0, 0.005)

    def run(blend: float) -> np.ndarray:
        core = TickCore(presets[0], Timing(param_blend=blend), ProceduralHorse(), mode=Mode.PROCEDURAL)
        out = []
        for i, t in enumerate(times):
            if i in changes:
                core.set_model(presets[changes[i]])
            out.append(core.step(float(t)).rider)
        return np.array(out)

    horse = ProceduralHorse()
    horses = [list(horse.sample(float(t))) for t in times]
    alone = np.array([[m.evaluate(h) for h in horses] for m in presets])
    motion = np.abs(np.diff(alone, axis=1)).max(axis=(0, 1))
    largest_delta = np.abs(alone[:, None] - alone[None, :]).max(axis=(0, 1, 2))
    bound = motion + len(changes) * 1.5 * largest_delta * 0.005 / 0.5 + 1e-9
    assert np.all(np.abs(np.diff(run(0.5), axis=0)).max(axis=0) <= bound)
    assert np.any(np.abs(np.diff(run(0.0), axis=0)).max(axis=0) > bound), "switching at once would jump"


def test_a_non_finite_rules_output_touches_no_state() -> None:
    core = TickCore(RiderModel(params=SMOOTH, scale=25.0), TIMING, ProceduralHorse())
    feed(core, lambda t: 2.0, 0.0, 0.3)
    kept = list(core.last_rider or [])
    core.push_input(1, 0.3, 0.3, [math.nan] * len(HORSE_NAMES))
    result = core.step(0.3)
    assert not np.isfinite(result.rider).all() and result.driver is Driver.INPUT
    assert core.last_rider == kept and core.resets == 0
