"""The skinned chain: shortest-arc alignment, torsion springs, fan-out sub-chains."""

from __future__ import annotations

import math

import numpy as np

from riderlive.physics import chain, quaternion
from riderlive.physics.chain import ChainModel
from riderlive.physics.config import PhysicsConfig
from riderlive.physics.drive import FixedStepper
from riderlive.physics.outputs import local_rotations
from riderlive.physics.skinned import BRAID, CLOTH_L, CLOTH_R, TAIL, SkinnedModel
from tests.physics.motion import planar

DT = 1.0 / 240.0
BONES = 11


def hanging_chain() -> np.ndarray:
    x = np.zeros((BONES + 1, 3, 1))
    x[:, 1, 0] = -0.08 * np.arange(BONES + 1)
    return x


def model() -> ChainModel:
    cfg = PhysicsConfig().skinned
    return ChainModel(DT, cfg.twist_rate, cfg.fan_gain, cfg.fan_max, cfg.fan_time, chain.fan_profile(BONES, [True]))


def spin(rate: float, seconds: float) -> chain.ChainState:
    """Turn bone 0's anchor about the (vertical) chain at ``rate`` rad/s."""
    x = hanging_chain()
    state = chain.rest_state(x, np.array([[1.0], [0.0], [0.0]]))
    m = model()
    for k in range(1, int(seconds / DT) + 1):
        phi = rate * k * DT
        up = np.array([[math.cos(phi)], [0.0], [math.sin(phi)]])  # a right-handed turn about -y, the bone axis
        state = chain.step(m, state, x, up)
    return state


def test_fan_out_grows_with_torsional_velocity_and_toward_the_tip() -> None:
    slow, fast = spin(0.5, 4.0), spin(1.0, 4.0)
    for state, rate in ((slow, 0.5), (fast, 1.0)):
        # steady state: the whole chain turns with the anchor
        assert np.allclose(state.twist_velocity[:, 0], rate, rtol=0.02)
        fan = state.fan[:, 0]
        assert np.all(fan[: BONES // 2] == 0.0)  # upper half: no sub-chains
        assert np.all(np.diff(fan[BONES // 2 :]) > 0.0)  # more toward the tip
    assert np.all(fast.fan[BONES // 2 :, 0] > 1.9 * slow.fan[BONES // 2 :, 0])  # in proportion to the velocity


def test_twist_propagates_until_uniform() -> None:
    x = hanging_chain()
    state = chain.rest_state(x, np.array([[1.0], [0.0], [0.0]]))
    m = model()
    turn = math.radians(60.0)
    up = np.array([[math.cos(turn)], [0.0], [math.sin(turn)]])
    state = chain.step(m, state, x, up)  # the anchor twists at once...
    assert abs(math.degrees(math.atan2(state.up[-1, 2, 0], state.up[-1, 0, 0]))) < 1.0  # ...the tip not yet
    for _ in range(int(4.0 / DT)):
        state = chain.step(m, state, x, up)
    angles = np.degrees(np.arctan2(state.up[:, 2, 0], state.up[:, 0, 0]))
    assert np.allclose(angles, 60.0, atol=0.5)  # every bone now carries the same twist
    assert np.all(state.fan == 0.0) or state.fan.max() < 1e-3


def test_zero_torsional_input_keeps_twist_zero_and_subchains_on_the_centre() -> None:
    sk = SkinnedModel.build(PhysicsConfig())
    stepper = FixedStepper(sk.step, sk.initial(planar(0.0)), 240.0)
    midplane = [TAIL, BRAID]  # the cloth flaps hang off the midplane: a pitch turns them about their own axes too
    for k in range(1, 61):
        stepper.advance_to(k / 30.0, planar)
        state = stepper.state
        assert np.abs(state.bones.twist_velocity[:, midplane]).max() < 1e-9
        assert np.abs(state.bones.fan).max() < 1e-12
        twist = quaternion.twist_angle(local_rotations(state), np.array([1.0, 0.0, 0.0]))
        assert np.abs(twist[:, midplane]).max() < 1e-9
        # The flaps' twists are mirror images: equal and opposite.
        np.testing.assert_allclose(twist[:, CLOTH_L], -twist[:, CLOTH_R], rtol=0.0, atol=1e-9)
        velocity = state.bones.twist_velocity
        np.testing.assert_allclose(velocity[:, CLOTH_L], -velocity[:, CLOTH_R], rtol=0.0, atol=1e-9)
    moved = stepper.state.strands.x[-1, :, 0] - stepper.state.strands.x[1, :, 0]
    assert abs(moved[2]) < 1e-9 and np.linalg.norm(moved[:2]) > 0.1  # it did swing, in the plane
