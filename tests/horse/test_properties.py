"""Property tests: any valid script gives finite frames, hooves never below the ground, live == batch."""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from riderlive.channels import HORSE_INDEX
from riderlive.horse import GAIT_TABLE, GAITS, MOVES, Gait, generate
from riderlive.horse.model import Model, step
from riderlive.horse.script import Segment, ShotScript

HOOF_HEIGHTS = [HORSE_INDEX[f"{leg}Hoof.ty"] for leg in ("lf", "rf", "lb", "rb")]


@st.composite
def segments(draw: st.DrawFn) -> Segment:
    if draw(st.booleans()):
        return Segment(move=draw(st.sampled_from(MOVES)), seconds=draw(st.none() | st.floats(0.05, 3.0)))
    gait = draw(st.sampled_from((*GAITS, "halt")))
    seconds = draw(st.floats(0.02, 2.0))
    if gait == "halt":
        return Segment(gait=gait, seconds=seconds)
    lo, hi = GAIT_TABLE[Gait(gait)].speed
    speed = draw(st.none() | st.floats(lo, hi))
    ramp = draw(st.none() | st.floats(0.1, 3.0))
    return Segment(gait=gait, seconds=seconds, speed=speed, ramp=ramp)


scripts = st.builds(
    lambda segs, seed: ShotScript(segment=segs, seed=seed),
    st.lists(segments(), min_size=1, max_size=6),
    st.none() | st.integers(0, 2**63 - 1),
)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(script=scripts, rate=st.floats(30.0, 1000.0))
def test_any_script_is_finite_and_above_ground(script: ShotScript, rate: float) -> None:
    table = generate(script, rate)
    assert np.all(np.isfinite(table.values))
    assert table.values[:, HOOF_HEIGHTS].min() >= -1e-12
    assert np.all(np.abs(table.values[:, HORSE_INDEX["rearPivot.rz"]]) <= 60.0)


@settings(max_examples=15, deadline=None)
@given(script=scripts)
def test_live_steps_equal_the_batch(script: ShotScript) -> None:
    table = generate(script, 60.0)
    model = script.model()
    state = script.start(model)
    live = []
    for t in table.t if table.t is not None else []:
        state, frame = step(model, state, float(t))
        live.append(frame)
    np.testing.assert_allclose(np.array(live), table.values, rtol=0, atol=1e-9)


def test_default_model_has_no_variation() -> None:
    assert Model().variation == 0.0
