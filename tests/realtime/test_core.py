"""TickCore: drivers, takeover blends, easing to neutral, procedural resume."""

from __future__ import annotations

import numpy as np

from riderlive.channels import HORSE_INDEX, HORSE_NAMES
from riderlive.horse import ProceduralHorse
from riderlive.realtime.core import Driver, Mode, TickCore, Timing
from riderlive.rules import RiderModel

TIMING = Timing(delay=0.0, hold=0.1, ease_time=0.5, blend_time=0.2, resume_after=1.0, fallback_procedural=True)
MODEL = RiderModel(scale=25.0)


def frame(rz: float) -> list[float]:
    f = [0.0] * len(HORSE_NAMES)
    f[HORSE_INDEX["rearPivot.rz"]] = rz
    f[HORSE_INDEX["rfHoof.ty"]] = 0.2
    return f


def run(core: TickCore, start: float, stop: float, dt: float = 0.01) -> list:
    return [core.step(t) for t in np.arange(start, stop, dt)]


def test_starts_procedural_and_input_takes_over_with_a_blend() -> None:
    core = TickCore(MODEL, Timing(delay=0.0, hold=1.0, blend_time=0.2), ProceduralHorse())
    assert core.step(0.0).driver is Driver.PROCEDURAL
    before = core.step(0.01).rider
    core.push_input(7, 100.0, 0.015, frame(3.0))
    out = run(core, 0.02, 0.4)
    assert all(o.driver is Driver.INPUT for o in out)
    assert out[0].producer == 7
    target = MODEL.evaluate(frame(3.0))
    assert np.abs(np.array(out[0].rider) - before).max() < np.abs(np.array(target) - before).max() * 0.1
    np.testing.assert_allclose(out[-1].rider, target, atol=1e-12, err_msg="blend done after blend_time")


def test_stale_input_eases_to_neutral_then_procedural_resumes() -> None:
    core = TickCore(MODEL, TIMING, ProceduralHorse())
    core.push_input(1, 0.0, 0.0, frame(3.0))
    out = run(core, 0.0, 3.0)
    drivers = [o.driver for o in out]
    t_neutral = drivers.index(Driver.NEUTRAL) * 0.01
    t_back = drivers.index(Driver.PROCEDURAL) * 0.01
    assert abs(t_neutral - 0.11) < 0.015, "held for `hold`, then neutral"
    assert abs(t_back - t_neutral - 1.5) < 0.015, "procedural after ease_time + resume_after"
    neutral = MODEL.evaluate([0.0] * len(HORSE_NAMES))
    at_rest = out[int((t_neutral + 0.55) / 0.01)]
    np.testing.assert_allclose(at_rest.rider, neutral, atol=1e-12)


def test_without_fallback_neutral_stays_and_pinned_procedural_ignores_input() -> None:
    core = TickCore(MODEL, Timing(fallback_procedural=False), ProceduralHorse())
    assert core.step(0.0).driver is Driver.NEUTRAL
    assert all(o.driver is Driver.NEUTRAL for o in run(core, 0.01, 5.0, 0.1))
    pinned = TickCore(MODEL, TIMING, ProceduralHorse(), mode=Mode.PROCEDURAL)
    pinned.push_input(1, 0.0, 0.0, frame(3.0))
    assert pinned.step(0.01).driver is Driver.PROCEDURAL


def test_a_gone_producer_stops_at_once_and_its_late_frames_are_ignored() -> None:
    core = TickCore(MODEL, TIMING, ProceduralHorse())
    core.push_input(4, 0.0, 0.0, frame(1.0))
    assert core.step(0.01).driver is Driver.INPUT
    core.producer_gone(4)
    assert not core.push_input(4, 0.01, 0.011, frame(1.0))
    assert core.step(0.02).driver is Driver.NEUTRAL


def test_procedural_frames_are_converted_from_metres() -> None:
    horse = ProceduralHorse()
    in_cm = TickCore(RiderModel(scale=0.25), TIMING, horse)
    metres = horse.sample(0.3)
    got = in_cm.procedural_frame(0.3)
    i = HORSE_INDEX["lfHoof.tx"]
    assert abs(got[i] - metres[i] * 100.0) < 1e-9
    j = HORSE_INDEX["rearPivot.rz"]
    assert got[j] == metres[j]
