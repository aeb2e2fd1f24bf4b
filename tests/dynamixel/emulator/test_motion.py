"""The emulated servo's motion and thermal model (pure), and motion seen through the SDK."""

from __future__ import annotations

import itertools
import math
from dataclasses import replace

import pytest
from dynamixel_sdk import COMM_SUCCESS
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.dynamixel.emulator import EmulatedBus, motion
from riderlive.dynamixel.tables import Item

from ..conftest import ManualClock, SdkLink


def run(
    state: motion.MotionState, profile: motion.Profile, seconds: float, dt: float = 0.01
) -> list[motion.MotionState]:
    out = [state]
    for _ in range(round(seconds / dt)):
        out.append(motion.step(out[-1], profile, dt))
    return out


def move(distance: float, vmax: float, amax: float) -> motion.Profile:
    return motion.Profile(torque_on=True, goal_position=distance, max_velocity=vmax, max_acceleration=amax)


def test_register_units() -> None:
    assert motion.velocity_from_register(1) == pytest.approx(0.229 * 4096 / 60)
    assert motion.velocity_to_register(motion.velocity_from_register(123)) == 123
    assert motion.acceleration_from_register(1) == pytest.approx(214.577 * 4096 / 3600)


def test_trapezoid_time_matches_the_closed_form() -> None:
    vmax, amax, distance = 2000.0, 10_000.0, 3000.0
    states = run(motion.MotionState(0.0), move(distance, vmax, amax), 2.5, dt=0.001)
    arrival = next(i for i, s in enumerate(states) if s.position == distance and s.velocity == 0) * 0.001
    expected = distance / vmax + vmax / amax  # cruise + one ramp's worth of time
    assert arrival == pytest.approx(expected, abs=0.005)
    assert max(abs(s.velocity) for s in states) == pytest.approx(vmax)


def test_triangle_profile_when_the_move_is_short() -> None:
    vmax, amax, distance = 5000.0, 10_000.0, 400.0
    states = run(motion.MotionState(0.0), move(distance, vmax, amax), 1.0, dt=0.001)
    peak = max(s.velocity for s in states)
    assert peak == pytest.approx(math.sqrt(amax * distance), rel=0.03)
    arrival = next(i for i, s in enumerate(states) if s.position == distance) * 0.001
    assert arrival == pytest.approx(2 * math.sqrt(distance / amax), abs=0.005)


@settings(max_examples=40, deadline=None)
@given(
    st.floats(-3000, 3000),
    st.floats(100, 5000),
    st.one_of(st.just(math.inf), st.floats(1000, 50_000)),
    st.sampled_from([0.001, 0.004, 0.0173]),
)
def test_profile_respects_its_caps_and_arrives(distance: float, vmax: float, amax: float, dt: float) -> None:
    profile = move(distance, vmax, amax)
    states = run(motion.MotionState(0.0), profile, abs(distance) / vmax + vmax / min(amax, 1e9) + 0.2, dt=dt)
    assert states[-1].position == distance
    assert states[-1].velocity == 0.0
    for before, after in itertools.pairwise(states):
        assert abs(after.velocity) <= vmax + 1e-6
        # the acceleration cap holds, except the final substep that snaps onto the goal
        snap = 3.0 if after.position == distance else 1.0
        assert abs(after.velocity - before.velocity) <= snap * amax * dt + 1e-6 or math.isinf(amax)
        # never overshoots: the position stays between start and goal
        assert min(0.0, distance) - 1e-6 <= after.position <= max(0.0, distance) + 1e-6


def test_torque_off_holds_still() -> None:
    profile = replace(move(1000.0, 1000.0, math.inf), torque_on=False)
    states = run(motion.MotionState(5.0, velocity=300.0), profile, 0.5)
    assert states[-1].position == 5.0
    assert states[-1].effort == 0.0


def test_velocity_mode_ramps_to_the_goal_velocity() -> None:
    profile = motion.Profile(
        torque_on=True, goal_position=0, max_velocity=1e9, max_acceleration=1000.0, goal_velocity=500.0
    )
    states = run(motion.MotionState(0.0), profile, 1.0, dt=0.01)
    assert states[25].velocity == pytest.approx(250.0)
    assert states[-1].velocity == pytest.approx(500.0)
    assert states[-1].position == pytest.approx(0.5 * 500 * 0.5 + 500 * 0.5, rel=0.01)


def test_temperature_rises_with_effort_and_cools_without() -> None:
    thermal = motion.ThermalParams(ambient_c=25.0, full_effort_rise_c=80.0, time_constant_s=100.0)
    loaded = replace(move(0.0, 1.0, 1.0), external_load=1.0)
    hot = motion.step(motion.MotionState(0.0, temperature=25.0), loaded, 100.0, thermal)
    assert hot.temperature == pytest.approx(25.0 + 80.0 * (1 - math.exp(-1.0)))
    light = motion.step(motion.MotionState(0.0, temperature=25.0), replace(loaded, external_load=0.0), 100.0, thermal)
    assert light.temperature < 25.5
    idle = replace(loaded, torque_on=False)
    cooled = motion.step(hot, idle, 100.0, thermal)
    assert cooled.temperature == pytest.approx(25.0 + (hot.temperature - 25.0) * math.exp(-1.0))


def test_a_profiled_move_through_the_sdk(timed_bus: EmulatedBus, timed_sdk: SdkLink, clock: ManualClock) -> None:
    ph, port = timed_sdk.ph, timed_sdk.port
    assert ph.write4ByteTxRx(port, 1, 108, 100) == (COMM_SUCCESS, 0)  # 24,414 pulse/s^2
    assert ph.write4ByteTxRx(port, 1, 112, 200) == (COMM_SUCCESS, 0)  # 3,126 pulse/s
    assert ph.write1ByteTxRx(port, 1, 64, 1) == (COMM_SUCCESS, 0)
    assert ph.write4ByteTxRx(port, 1, 116, 2348) == (COMM_SUCCESS, 0)  # +300 pulses
    # A triangle: peak sqrt(a d) = 2,706 pulse/s after 111 ms, arrival after 222 ms.
    clock.advance(0.080)
    assert ph.read1ByteTxRx(port, 1, 122)[0] == 1  # Moving
    velocity = ph.read4ByteTxRx(port, 1, 128)[0]
    assert velocity == round(24_414 * 0.080 / (0.229 * 4096 / 60))
    present = ph.read4ByteTxRx(port, 1, 132)[0]
    assert present == pytest.approx(2048 + 0.5 * 24_414 * 0.080**2, abs=2)
    clock.advance(0.130)
    assert ph.read1ByteTxRx(port, 1, 122)[0] == 1  # still moving at 210 ms
    clock.advance(0.020)
    assert ph.read1ByteTxRx(port, 1, 122)[0] == 0  # arrived by 230 ms
    assert ph.read4ByteTxRx(port, 1, 132)[0] == 2348
    assert ph.read4ByteTxRx(port, 1, 128)[0] == 0
    assert timed_bus.read_item(1, Item.PRESENT_TEMPERATURE) == 25
