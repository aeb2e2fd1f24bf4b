"""Skeletons and rigs: unit quaternions, rest pose at neutral, hierarchy and IK invariants."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.channels import HORSE, HORSE_NAMES, RIDER, RIDER_NAMES, Kind
from riderlive.skeleton import (
    HORSE_NEUTRAL,
    HORSE_RIG,
    HUMANOID,
    bone_quaternions,
    hello_skeletons,
    horse_pose,
    quat,
    rider_pose,
    rider_rig,
)
from riderlive.skeleton.rig import Pose, Rig

RIDER_NEUTRAL = rider_rig().neutral


def _rider_values(deltas: list[float]) -> dict[str, float]:
    return {n: RIDER_NEUTRAL[n] + d for n, d in zip(RIDER_NAMES, deltas, strict=True)}


def _delta_for(kind: Kind) -> st.SearchStrategy[float]:
    if kind is Kind.ROTATION:
        return st.floats(-60.0, 60.0)
    if kind is Kind.TRANSLATION:
        return st.floats(-0.15, 0.15)
    return st.floats(-10.0, 10.0)


rider_deltas = st.tuples(*(_delta_for(c.kind) for c in RIDER)).map(list)
horse_deltas = st.tuples(*(_delta_for(c.kind) for c in HORSE)).map(list)


def _horse_values(deltas: list[float]) -> dict[str, float]:
    return {n: HORSE_NEUTRAL.get(n, 0.0) + d for n, d in zip(HORSE_NAMES, deltas, strict=True)}


def _matrix(q: tuple[float, float, float, float]) -> np.ndarray:
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _fk_with_matrices(rig: Rig, pose: Pose) -> list[np.ndarray]:
    """Independent forward kinematics with rotation matrices."""
    rot: list[np.ndarray] = []
    pos: list[np.ndarray] = []
    for i, b in enumerate(rig.bones):
        local = _matrix(pose.local_rotations[i])
        off = np.array(pose.local_offsets[i])
        if b.parent < 0:
            rot.append(local)
            pos.append(off)
        else:
            rot.append(rot[b.parent] @ local)
            pos.append(pos[b.parent] + rot[b.parent] @ off)
    return pos


@pytest.mark.parametrize("rig", [rider_rig(), HORSE_RIG], ids=["rider", "horse"])
def test_hierarchy_is_a_tree_with_parents_first(rig: Rig) -> None:
    names = rig.names
    assert len(set(names)) == len(names)
    assert [b.parent for b in rig.bones].count(-1) == 1
    for i, b in enumerate(rig.bones):
        assert -1 <= b.parent < i
        assert all(math.isfinite(c) for c in b.offset)
        if b.parent >= 0:
            assert quat.norm(b.offset) > 0.01, f"{b.name} sits on its parent"


def test_left_bones_are_on_the_left_and_mirror_the_right() -> None:
    for rig, pairs in ((rider_rig(), (("lf_", "rt_"),)), (HORSE_RIG, (("lf", "rf"), ("lb", "rb")))):
        rest = dict(zip(rig.names, rig.rest_world(), strict=True))
        for name, p in rest.items():
            for left, right in pairs:
                if name.startswith(left):
                    q = rest[right + name[len(left) :]]
                    assert p[2] < 0.0 < q[2], name
                    assert p[0] == pytest.approx(q[0]) and p[1] == pytest.approx(q[1])
                    assert p[2] == pytest.approx(-q[2])


def test_every_moving_channel_drives_the_skeleton() -> None:
    def driven(rig: Rig) -> set[str]:
        names = {d.channel for d in (*rig.rotations, *rig.translations)}
        for c in rig.chains:
            names |= {o.channel for o in (*c.target, *c.pole)}
        return names

    rider_moving = {c.name for c in RIDER if c.kind is not Kind.ATTRIBUTE}
    assert driven(rider_rig()) == rider_moving
    # ground.ty is the ground's height under the horse: root.ty places the horse (docs/horse.md, Terrain)
    assert driven(HORSE_RIG) == set(HORSE_NAMES) - {"ground.ty"}


def test_neutral_values_give_the_rest_pose() -> None:
    for pose, rig in ((rider_pose(dict(RIDER_NEUTRAL)), rider_rig()), (horse_pose(HORSE_NEUTRAL), HORSE_RIG)):
        for q in pose.local_rotations:
            assert np.allclose(q, (0.0, 0.0, 0.0, 1.0), atol=1e-9)
        assert np.allclose(pose.world_positions, rig.rest_world(), atol=1e-9)
    flat = bone_quaternions([RIDER_NEUTRAL[n] for n in RIDER_NAMES])
    assert np.allclose(flat, [0.0, 0.0, 0.0, 1.0] * len(rider_rig().bones), atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(rider_deltas)
def test_rider_rotations_are_unit_and_fk_is_consistent(deltas: list[float]) -> None:
    rig = rider_rig()
    pose = rider_pose(_rider_values(deltas))
    for q in pose.local_rotations:
        assert all(math.isfinite(c) for c in q)
        assert math.fsum(c * c for c in q) == pytest.approx(1.0, abs=1e-9)
    assert np.allclose(_fk_with_matrices(rig, pose), pose.world_positions, atol=1e-9)
    # Rotations move bones, never stretch them: limb segments keep their rest length.
    for i, b in enumerate(rig.bones):
        if b.parent >= 0 and b.name.startswith(("lf_", "rt_")):
            seg = np.subtract(pose.world_positions[i], pose.world_positions[b.parent])
            assert np.linalg.norm(seg) == pytest.approx(quat.norm(b.offset), abs=1e-9)


@settings(max_examples=60, deadline=None)
@given(horse_deltas)
def test_horse_rotations_are_unit_and_fk_is_consistent(deltas: list[float]) -> None:
    pose = horse_pose(_horse_values(deltas))
    for q in pose.local_rotations:
        assert math.fsum(c * c for c in q) == pytest.approx(1.0, abs=1e-9)
    assert np.allclose(_fk_with_matrices(HORSE_RIG, pose), pose.world_positions, atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-0.08, 0.08), min_size=12, max_size=12))
def test_hooves_land_on_their_targets(moves: list[float]) -> None:
    values = dict(HORSE_NEUTRAL)
    rest = dict(zip(HORSE_RIG.names, HORSE_RIG.rest_world(), strict=True))
    for k, hoof in enumerate(("lf", "rf", "lb", "rb")):
        dx, dy, dz = moves[3 * k : 3 * k + 3]
        values[f"{hoof}Hoof.tx"] = HORSE_NEUTRAL.get(f"{hoof}Hoof.tx", 0.0) + dx
        values[f"{hoof}Hoof.ty"] = abs(dy)
        values[f"{hoof}Hoof.tz"] = dz
    pose = horse_pose(values)
    world = dict(zip(HORSE_RIG.names, pose.world_positions, strict=True))
    bones = {b.name: b for b in HORSE_RIG.bones}
    for hoof in ("lf", "rf", "lb", "rb"):
        # tx forward of the standing spot, ty above the ground, tz to the horse's right (+z).
        r = rest[f"{hoof}Hoof"]
        want = np.array((r[0] + values[f"{hoof}Hoof.tx"], values[f"{hoof}Hoof.ty"], r[2] + values[f"{hoof}Hoof.tz"]))
        middle = f"{hoof}Knee" if hoof[1] == "f" else f"{hoof}Hock"
        reach = quat.norm(bones[middle].offset) + quat.norm(bones[f"{hoof}Fetlock"].offset)
        fetlock_want = want - np.array(bones[f"{hoof}Hoof"].offset)
        root = np.array(world[f"{hoof}Leg"])
        got = np.array(world[f"{hoof}Hoof"])
        if np.linalg.norm(fetlock_want - root) < reach - 1e-6:
            assert np.allclose(got, want, atol=1e-7), hoof
        else:  # out of reach: the leg straightens toward the target
            fetlock = np.array(world[f"{hoof}Fetlock"])
            assert np.linalg.norm(fetlock - root) == pytest.approx(reach, abs=1e-6)
            towards = (fetlock_want - root) / np.linalg.norm(fetlock_want - root)
            assert np.allclose((fetlock - root) / reach, towards, atol=1e-6)


@settings(max_examples=40, deadline=None)
@given(st.floats(-0.06, 0.06), st.floats(-0.06, 0.06), st.floats(-0.03, 0.03), st.floats(-0.03, 0.03))
def test_wrists_reach_their_targets_and_follow_the_seat(tz: float, ty: float, cx: float, cy: float) -> None:
    values = dict(RIDER_NEUTRAL)
    for p in ("lf", "rt"):
        values[f"{p}_wrist.tz"] += tz
        values[f"{p}_wrist.ty"] += ty
    values["cog.tx"] += cx
    values["cog.ty"] += cy
    rig = rider_rig()
    rest = dict(zip(rig.names, rig.rest_world(), strict=True))
    world = dict(zip(rig.names, rider_pose(values).world_positions, strict=True))
    for p in ("lf", "rt"):
        r = rest[f"{p}_hand"]
        assert np.allclose(world[f"{p}_hand"], (r[0] + tz + cx, r[1] + ty + cy, r[2]), atol=1e-7)


def test_signs_follow_the_documented_convention() -> None:
    rig = rider_rig()
    head = rig.index["head"]
    rest_head = rig.rest_world()[head]

    def head_at(**deltas: float) -> tuple[float, float, float]:
        values = dict(RIDER_NEUTRAL)
        for name, d in deltas.items():
            values[name.replace("__", ".")] += d
        return rider_pose(values).world_positions[head]

    assert head_at(lower_back__rz=10.0)[0] > rest_head[0] + 0.05  # forward lean
    assert head_at(lower_back__ry=10.0)[2] > rest_head[2] + 0.05  # lean right
    assert head_at(cog__ty=0.05)[1] == pytest.approx(rest_head[1] + 0.05)
    nose = HORSE_RIG.index["muzzle"]
    rest_nose = HORSE_RIG.rest_world()[nose]
    up = horse_pose({**HORSE_NEUTRAL, "rearPivot.rz": 10.0}).world_positions[nose]
    assert up[1] > rest_nose[1] + 0.1  # pitch up lifts the front
    rolled = horse_pose({**HORSE_NEUTRAL, "rearPivot.rx": 10.0}).world_positions[HORSE_RIG.index["saddle"]]
    assert rolled[2] > 0.05  # + rolls to the right (right-handed about +x): the body above the pivot leans to +z
    toes = rig.index["lf_toes"]
    lifted = rider_pose({**RIDER_NEUTRAL, "lf_foot.rz": RIDER_NEUTRAL["lf_foot.rz"] + 20.0})
    assert lifted.world_positions[toes][1] > rig.rest_world()[toes][1] + 0.02


def test_bad_values_are_refused_or_held_at_neutral() -> None:
    with pytest.raises(ValueError, match="37"):
        bone_quaternions([0.0] * 5)
    values = dict(RIDER_NEUTRAL)
    values["lower_back.rz"] = math.nan
    values["cog.ty"] = math.inf
    assert np.allclose(bone_quaternions(values), [0.0, 0.0, 0.0, 1.0] * len(rider_rig().bones), atol=1e-9)


def test_hello_is_strict_json_with_a_complete_humanoid_map() -> None:
    hello = hello_skeletons()
    text = json.dumps(hello, allow_nan=False)
    back = json.loads(text)
    assert [b["name"] for b in back["rider"]["bones"]] == list(rider_rig().names)
    assert back["axes"]["forward"] == "+x" and back["axes"]["up"] == "+y"
    unity = [b["unity"] for b in back["rider"]["bones"] if b["unity"]]
    assert len(unity) == len(set(unity)) == len(HUMANOID)
    for required in ("Hips", "Spine", "Head", "LeftUpperArm", "RightLowerLeg", "LeftFoot"):
        assert required in unity
    vrm = {b["vrm"] for b in back["rider"]["bones"] if b["vrm"]}
    assert {"hips", "leftHand", "rightUpperLeg"} <= vrm


ENGINE_AXES = {
    "unity": (quat.to_unity, lambda a: (a[2], a[1], a[0])),
    "unreal": (quat.to_unreal, lambda a: (a[0], a[2], a[1])),
    "godot": (quat.to_godot, lambda a: (a[2], a[1], -a[0])),
}


@pytest.mark.parametrize("engine", sorted(ENGINE_AXES))
@settings(max_examples=50, deadline=None)
@given(
    axis=st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)).filter(lambda a: quat.norm(a) > 0.1),
    angle=st.floats(-180.0, 180.0),
    v=st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)),
)
def test_engine_conversions_commute_with_rotation(engine: str, axis: quat.Vec3, angle: float, v: quat.Vec3) -> None:
    """Converting then rotating equals rotating then converting (engines rotate with q v q*)."""
    convert, position = ENGINE_AXES[engine]
    q = quat.from_axis_angle(quat.unit(axis), angle)
    assert np.allclose(quat.rotate(convert(q), position(v)), position(quat.rotate(q, v)), atol=1e-9)


@pytest.mark.parametrize("rig", [rider_rig(), HORSE_RIG], ids=["rider", "horse"])
def test_the_array_path_poses_every_frame_like_the_float_path(rig: Rig) -> None:
    """One solver source on two backends: N frames at once equal N single frames, to 1e-12."""
    from riderlive.skeleton.rig import solve, solve_frames

    rng = np.random.default_rng(7)
    names = sorted(
        {d.channel for d in (*rig.rotations, *rig.translations)}
        | {o.channel for c in rig.chains for o in (*c.target, *c.pole)}
    )
    frames = 64
    columns = {}
    for name in names:
        spread = 40.0 if name.split(".")[1].startswith("r") else 0.2
        columns[name] = rig.neutral.get(name, 0.0) + rng.uniform(-spread, spread, frames)
    # Degenerate and bad inputs: NaN and inf count as neutral; a foot target far out of reach.
    columns[names[0]][3] = math.nan
    columns[names[-1]][5] = math.inf
    reach = next(o.channel for c in rig.chains for o in c.target)
    columns[reach][9] = 50.0
    batch = solve_frames(rig, columns, frames)
    for f in range(frames):
        one = solve(rig, {n: float(v[f]) for n, v in columns.items()})
        np.testing.assert_allclose(batch.local_rotations[:, f], one.local_rotations, atol=1e-12)
        np.testing.assert_allclose(batch.local_offsets[:, f], one.local_offsets, atol=1e-12)
        np.testing.assert_allclose(batch.world_rotations[:, f], one.world_rotations, atol=1e-12)
        np.testing.assert_allclose(batch.world_positions[:, f], one.world_positions, atol=1e-12)
