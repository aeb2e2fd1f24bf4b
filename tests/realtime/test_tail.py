"""The tail and braid as the tick runs them: equal to an offline run, tick-rate independent, always finite."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from riderlive.channels import HORSE, HORSE_INDEX, RIDER, Kind
from riderlive.horse import ProceduralHorse
from riderlive.physics.drive import FixedStepper, TakeSource
from riderlive.physics.outputs import channel_names, publish
from riderlive.physics.skinned import SkinnedModel
from riderlive.realtime.edges import UnitEdges
from riderlive.realtime.tail import TickPhysics, physics_channels
from riderlive.rules.engine import RiderModel
from riderlive.rules.params import load_preset

RULES = RiderModel(params=load_preset("kuhnel2003"), scale=25.0)


def tick_frames(rate: float, seconds: float, offset: float = 3.1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Procedural gallop frames at tick times (engine seconds from ``offset``) and the rules' rider."""
    horse = ProceduralHorse("gallop", 12.0, seed=3)
    times = offset + np.arange(int(seconds * rate)) / rate
    h = np.array([horse.sample(float(t)) for t in times])
    return times, h, RULES.evaluate_batch(h)


def assert_matches_offline(live: np.ndarray, offline: np.ndarray, names: tuple[str, ...]) -> None:
    """Live (tick) values equal an offline run on the same frames, to rounding.

    A step whose end time rounds a hair (< 1e-15 s) past a tick's time sees that tick's
    frame held in the tick (the next frame does not exist yet) and a 1e-13 extrapolation
    offline (``TakeSource`` already knows the next row); the solver carries that on.
    Measured: <= 1e-10 m for positions, <= 2e-8 deg for angles over a few seconds.
    """
    diff = np.abs(live - offline)
    lengths = np.array([n.split(".")[1] in ("tx", "ty", "tz", "fan") for n in names])
    assert np.isfinite(live).all()
    assert diff[:, lengths].max() <= 1e-9, f"positions differ by {diff[:, lengths].max():.2e} m"
    assert diff[:, ~lengths].max() <= 1e-6, f"angles differ by {diff[:, ~lengths].max():.2e} deg"


def run_live(physics: TickPhysics, times: np.ndarray, h: np.ndarray, r: np.ndarray) -> np.ndarray:
    return np.array([physics.tick(float(t), h[i].tolist(), r[i].tolist()) for i, t in enumerate(times)])


def test_channels_are_the_physics_outputs() -> None:
    names = physics_channels()
    assert names == channel_names(SkinnedModel.build(TickPhysics(None, UnitEdges(25.0)).config))
    assert any(n.startswith("tail_10.") for n in names) and any(n.startswith("braid_10.") for n in names)


def test_tick_equals_an_offline_run_on_the_same_frames() -> None:
    times, h, r = tick_frames(120.0, 2.0)
    physics = TickPhysics(None, UnitEdges(25.0))
    live = run_live(physics, times, h, r)
    model = physics.model
    source = TakeSource(times - times[0], h, r)  # as a take records it: t from 0 at the first tick
    stepper = FixedStepper(model.step, model.initial(source(0.0)), model.config.rate)
    offline = []
    for t in times - times[0]:
        stepper.advance_to(float(t), source)
        offline.append(publish(model, stepper.state))
    assert_matches_offline(live, np.array(offline), physics.names)
    rz = [i for i, n in enumerate(physics.names) if n.startswith("tail_0") and n.endswith(".rz")]
    assert live[:, rz].std(axis=0).max() > 1.0, "the tail swings (deg) while the horse gallops"


@pytest.mark.parametrize("rate", [120.0, 500.0])
def test_the_internal_step_is_fixed_whatever_the_tick_rate(rate: float) -> None:
    times, h, r = tick_frames(rate, 1.0)
    physics = TickPhysics(None, UnitEdges(25.0))
    run_live(physics, times, h, r)
    assert physics.stepper is not None
    assert physics.stepper.steps == int(np.floor((times[-1] - times[0]) * 240.0 + 1e-6))
    assert physics.stepper.rate == 240.0


def test_service_length_units_scale_positions_not_rotations() -> None:
    times, h, r = tick_frames(120.0, 0.5)
    metres = run_live(TickPhysics(None, UnitEdges(25.0)), times, h, r)
    scale = 2.5  # the service speaks decimetres: lengths are 10x the metre values
    lengths = [i for i, c in enumerate(HORSE) if c.kind is Kind.TRANSLATION]
    rider_lengths = [i for i, c in enumerate(RIDER) if c.kind is Kind.TRANSLATION]
    h10, r10 = h.copy(), r.copy()
    h10[:, lengths] *= 10.0
    r10[:, rider_lengths] *= 10.0
    physics = TickPhysics(None, UnitEdges(scale))
    decimetres = run_live(physics, times, h10, r10)
    is_length = np.array([n.split(".")[1] in ("tx", "ty", "tz", "fan") for n in physics.names])
    np.testing.assert_allclose(decimetres[:, is_length], 10.0 * metres[:, is_length], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(decimetres[:, ~is_length], metres[:, ~is_length], rtol=1e-7, atol=1e-7)


def test_bad_frames_never_reach_the_output() -> None:
    times, h, r = tick_frames(120.0, 0.5)
    h[20:30, HORSE_INDEX["root.ty"]] = np.inf  # the tick guards its frames; the physics holds anyway
    h[40, HORSE_INDEX["rearPivot.rz"]] = 1e300  # absurd but finite: the strands may blow up
    physics = TickPhysics(None, UnitEdges(25.0))
    out = run_live(physics, times, h, r)
    assert np.isfinite(out).all()
    assert physics.stepper is not None
    assert physics.stepper.bad_inputs > 0 or physics.errors > 0


def step_over_slew(before: np.ndarray, first: np.ndarray) -> float:
    """The largest |first - last of ``before``| over that channel's largest per-tick step in ``before``."""
    slew = np.abs(np.diff(before, axis=0)).max(axis=0)
    moving = slew > 1e-9
    return float((np.abs(first - before[-1])[moving] / slew[moving]).max())


def test_strands_handed_over_go_on_as_if_uninterrupted() -> None:
    """A spare restoring the dead tick's strands (pickled, as in the snapshot) and ticking the
    same frames gives the values of a tick that never stopped."""
    times, h, r = tick_frames(120.0, 3.0)
    whole = run_live(TickPhysics(None, UnitEdges(25.0)), times, h, r)
    dead = TickPhysics(None, UnitEdges(25.0))
    k = 240
    run_live(dead, times[:k], h[:k], r[:k])
    tail = dead.capture()
    assert tail is not None
    spare = TickPhysics(None, UnitEdges(25.0))
    assert spare.restore(pickle.loads(pickle.dumps(tail)))
    after = run_live(spare, times[k:], h[k:], r[k:])
    assert_matches_offline(after, whole[k:], spare.names)
    assert spare.status()["steps"] == dead.status()["steps"] + len(times[k:]) * 2  # 240 Hz steps at 120 Hz ticks


@pytest.mark.parametrize(("gap", "bound"), [(0, 0.25), (3, 1.0)])
def test_a_takeover_moves_the_tail_as_the_uninterrupted_one(gap: int, bound: float) -> None:
    """The snapshot is a tick older than the last frame published (written at ~60 Hz), the new
    generation ticks ``gap`` deadlines later: its tail differs from one that never stopped by
    less than one tick's motion (its largest per-tick step in the second before; a quarter
    without a gap: across one the strands see the horse interpolated over the frames nobody
    ticked), so there is no jump larger than one tick's; restarted from rest (before the
    hand-over) it differs by many ticks' motion."""
    times, h, r = tick_frames(120.0, 3.0)
    dead = TickPhysics(None, UnitEdges(25.0))
    k = 240
    values = run_live(dead, times[: k - 1], h[: k - 1], r[: k - 1])
    tail = dead.capture()
    assert tail is not None
    first = k + gap
    values = np.vstack([values, run_live(dead, times[k - 1 : first + 1], h[k - 1 : first + 1], r[k - 1 : first + 1])])
    slew = np.abs(np.diff(values[k - 121 : k], axis=0)).max(axis=0)
    moving = slew > 1e-9
    spare = TickPhysics(None, UnitEdges(25.0))
    assert spare.restore(tail)
    resumed = np.array(spare.tick(float(times[first]), h[first].tolist(), r[first].tolist()))
    error = (np.abs(resumed - values[first]) / np.where(moving, slew, 1.0))[moving].max()
    assert error <= bound, f"the handed-over tail is {error:.2f} ticks' motion off"
    from_rest = np.array(
        TickPhysics(None, UnitEdges(25.0)).tick(float(times[first]), h[first].tolist(), r[first].tolist())
    )
    assert (np.abs(from_rest - values[first]) / np.where(moving, slew, 1.0))[moving].max() > 5.0


def test_strands_of_another_physics_file_are_not_restored() -> None:
    dead = TickPhysics(None, UnitEdges(25.0))
    times, h, r = tick_frames(120.0, 0.2)
    run_live(dead, times, h, r)
    tail = dead.capture()
    assert tail is not None
    spare = TickPhysics(None, UnitEdges(25.0))
    spare.names = spare.names[:-1]  # another file's channels
    assert not spare.restore(tail) and spare.stepper is None
