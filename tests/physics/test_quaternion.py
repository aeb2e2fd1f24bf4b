"""Shortest-arc rotations and the quaternion helpers (property tests)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.physics import chain, quaternion

coord = st.floats(-1.0, 1.0, allow_nan=False)
vector = st.tuples(coord, coord, coord).filter(lambda v: np.linalg.norm(v) > 1e-3)


def unit(v: tuple[float, float, float]) -> np.ndarray:
    a = np.array(v)
    return a / np.linalg.norm(a)


@settings(max_examples=150, deadline=None)
@given(vector, vector)
def test_shortest_arc_is_unit_maps_a_to_b_and_has_no_twist(va, vb) -> None:
    a, b = unit(va), unit(vb)
    q = quaternion.shortest_arc(a, b)
    assert abs(np.linalg.norm(q) - 1.0) < 1e-12
    assert np.allclose(quaternion.rotate(q, a), b, atol=1e-6)
    # no twist about a: the rotation axis is perpendicular to a
    assert abs(np.dot(q[:3], a)) < 1e-9
    assert abs(quaternion.twist_angle(q, a)) < 1e-6


@settings(max_examples=60, deadline=None)
@given(vector)
def test_shortest_arc_antiparallel(va) -> None:
    a = unit(va)
    q = quaternion.shortest_arc(a, -a)
    assert abs(np.linalg.norm(q) - 1.0) < 1e-12
    assert np.allclose(quaternion.rotate(q, a), -a, atol=1e-6)
    assert abs(np.dot(q[:3], a)) < 1e-9  # a half turn about an axis perpendicular to a


def test_shortest_arc_identity_and_batch() -> None:
    a = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    b = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    q = quaternion.shortest_arc(a, b)
    assert np.allclose(q[0], quaternion.IDENTITY)
    assert np.allclose(quaternion.rotate(q, a), b, atol=1e-12)


@settings(max_examples=80, deadline=None)
@given(vector, vector, st.floats(-np.pi, np.pi))
def test_carry_matches_the_shortest_arc_quaternion(va, vb, angle) -> None:
    a, b = unit(va), unit(vb)
    if np.dot(a, b) < -0.99:
        return  # carry() documents that a and b must not be (nearly) opposite
    v = quaternion.rotate(quaternion.from_axis_angle(a, angle), quaternion.perpendicular(a))
    expected = quaternion.rotate(quaternion.shortest_arc(a, b), v)
    got = np.array(chain.carry(tuple(a), tuple(b), tuple(v)))  # the kernels' helper, run by Python
    assert np.allclose(got, expected, atol=1e-9)


@settings(max_examples=80, deadline=None)
@given(st.floats(-179, 179), st.floats(-89, 89), st.floats(-179, 179))
def test_euler_round_trip(rx, ry, rz) -> None:
    q = quaternion.from_euler_xyz(np.array([rx, ry, rz]))
    assert np.allclose(quaternion.to_euler_xyz(q), [rx, ry, rz], atol=1e-6)
    m = quaternion.to_matrix(q)
    assert np.allclose(m, quaternion.rotation_z(rz) @ quaternion.rotation_y(ry) @ quaternion.rotation_x(rx), atol=1e-12)
    back = quaternion.from_matrix(m)
    assert np.allclose(back, q if q[3] >= 0 else -q, atol=1e-9)


def test_shortest_arc_nearly_antiparallel() -> None:
    """1e-5 rad from opposite: the cross product still defines the axis (found by hypothesis)."""
    a, b = unit((1.0, 0.0, 1e-5)), np.array([-1.0, 0.0, 0.0])
    q = quaternion.shortest_arc(a, b)
    assert np.allclose(quaternion.rotate(q, a), b, atol=1e-9)
    assert abs(np.dot(q[:3], a)) < 1e-9
