"""The rider as a VMC performer: type tags, names, unit quaternions, golden bundles, and a round trip.

The round trip uses the conversion ``docs/vmc.md`` documents, written here from the
doc (matrices, not the service's quaternion code): Unity -> ours, then the avatar's
world rotations ``A = A_parent L``, then ``W = A S^-1``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.channels import HORSE_NAMES, RIDER, RIDER_NAMES, Kind
from riderlive.horse import DEFAULT_SCALE
from riderlive.rules import RiderModel
from riderlive.skeleton import HORSE_RIG, HUMANOID, horse_pose, rider_pose, rider_rig
from riderlive.vmc.performer import horse_bundle, rider_bundle, tpose_turns

osc_bundle = pytest.importorskip("pythonosc.osc_bundle")
GOLDEN = Path(__file__).with_name("golden")
UNITY_HUMAN_BODY_BONES = {
    # UnityEngine.HumanBodyBones (the names VMC marionettes look up), body and limbs.
    "Hips", "LeftUpperLeg", "RightUpperLeg", "LeftLowerLeg", "RightLowerLeg", "LeftFoot", "RightFoot", "Spine",
    "Chest", "UpperChest", "Neck", "Head", "LeftShoulder", "RightShoulder", "LeftUpperArm", "RightUpperArm",
    "LeftLowerArm", "RightLowerArm", "LeftHand", "RightHand", "LeftToes", "RightToes", "LeftEye", "RightEye", "Jaw",
}  # fmt: skip
NEUTRAL = rider_rig().neutral


def _messages(data: bytes) -> list[tuple[str, str, list[Any]]]:
    """(address, type tags, arguments) of every message in a bundle, by python-osc."""
    bundle = osc_bundle.OscBundle(data)
    out = []
    for m in bundle:
        tags = m.dgram[len(m.address) + 4 - len(m.address) % 4 :].split(b"\x00", 1)[0].decode()
        out.append((m.address, tags.removeprefix(","), list(m.params)))
    return out


def _frame(deltas: dict[str, float] | None = None) -> list[float]:
    values = dict(NEUTRAL)
    values.update(deltas or {})
    return [values[n] for n in RIDER_NAMES]


def _rules_frame() -> tuple[list[float], list[float]]:
    """A fixed, asymmetric horse frame and what the default rules make of it."""
    horse = [0.0] * len(HORSE_NAMES)
    for name, value in (("lfHoof.tx", 0.2), ("rbHoof.ty", 0.1), ("rearPivot.rz", 6.0), ("rearPivot.rx", -4.0),
                        ("backMid.rz", 3.0), ("rearPivot.ty", 0.05), ("root.ry", 20.0)):  # fmt: skip
        horse[HORSE_NAMES.index(name)] = value
    return horse, list(RiderModel(scale=DEFAULT_SCALE).evaluate(horse))


def _bundles() -> dict[str, bytes]:
    horse, rider = _rules_frame()
    hp = horse_pose(horse)
    saddle = HORSE_RIG.index["saddle"]
    return {
        "rider_neutral": rider_bundle(rider_pose(_frame()), (0.0, 1.46, 0.0), (0.0, 0.0, 0.0, 1.0), 0.0),
        "rider_rules": rider_bundle(rider_pose(rider), hp.world_positions[saddle], hp.world_rotations[saddle], 2.5),
        "horse_rules": horse_bundle(hp, HORSE_RIG.names, 2.5),
    }


@pytest.mark.parametrize("name", ["rider_neutral", "rider_rules", "horse_rules"])
def test_bundles_match_their_golden_files(name: str) -> None:
    """Decoded by python-osc, to float32 precision. Regenerate: RIDERLIVE_GOLDEN=write pytest tests/vmc."""
    decoded = [
        [a, t, [round(v, 6) if isinstance(v, float) else v for v in args]] for a, t, args in _messages(_bundles()[name])
    ]
    path = GOLDEN / f"{name}.json"
    if os.environ.get("RIDERLIVE_GOLDEN") == "write":
        path.write_text("[\n" + ",\n".join(json.dumps(m) for m in decoded) + "\n]\n")
    golden = json.loads(path.read_text())
    assert [m[:2] for m in decoded] == [m[:2] for m in golden]
    for got, want in zip(decoded, golden, strict=True):
        assert got[2][:1] == want[2][:1] or got[1] != "sfffffff"
        np.testing.assert_allclose(
            [v for v in got[2] if not isinstance(v, str)], [v for v in want[2] if not isinstance(v, str)], atol=2e-6
        )


def test_type_tags_and_bone_names() -> None:
    messages = _messages(_bundles()["rider_rules"])
    assert messages[0] == ("/VMC/Ext/OK", "iii", [1, 3, 0])
    assert messages[1][:2] == ("/VMC/Ext/T", "f")
    assert messages[2][:3] == ("/VMC/Ext/Root/Pos", "sfffffff", messages[2][2]) and messages[2][2][0] == "root"
    bones = messages[3:]
    assert all(address == "/VMC/Ext/Bone/Pos" and tags == "sfffffff" for address, tags, _ in bones)
    names = [args[0] for _, _, args in bones]
    assert names[0] == "Hips"
    assert set(names) == {unity for unity, _ in HUMANOID.values()}
    assert set(names) <= UNITY_HUMAN_BODY_BONES
    horse = _messages(_bundles()["horse_rules"])
    assert [args[0] for _, _, args in horse[3:]] == list(HORSE_RIG.names)


def _delta(kind: Kind) -> st.SearchStrategy[float]:
    return st.floats(-40.0, 40.0) if kind is Kind.ROTATION else st.floats(-0.1, 0.1)


@settings(max_examples=25, deadline=None)
@given(st.tuples(*(_delta(c.kind) for c in RIDER)))
def test_every_quaternion_sent_is_unit(deltas: tuple[float, ...]) -> None:
    frame = [NEUTRAL[n] + d for n, d in zip(RIDER_NAMES, deltas, strict=True)]
    for address, _, args in _messages(rider_bundle(rider_pose(frame), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), 1.0)):
        if address.endswith("/Pos"):
            assert abs(np.linalg.norm(args[4:8]) - 1.0) < 1e-6


def _matrix(q: list[float] | np.ndarray) -> np.ndarray:
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


UNITY = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
"""Ours -> Unity for positions (a reflection: swap x and z). A rotation matrix maps as UNITY R UNITY."""


def _avatar(messages: list[tuple[str, str, list[Any]]]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """World (rotation, position) of each humanoid bone in Unity's axes, from the bundle alone."""
    parent_of = {}
    rig = rider_rig()
    for name, (unity, _) in HUMANOID.items():
        p = rig.bones[rig.index[name]].parent
        while p >= 0 and rig.bones[p].name not in HUMANOID:
            p = rig.bones[p].parent
        parent_of[unity] = None if p < 0 else HUMANOID[rig.bones[p].name][0]
    world: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for address, _, args in messages:
        if address != "/VMC/Ext/Bone/Pos":
            continue
        name, pos, rot = args[0], np.array(args[1:4]), _matrix(args[4:8])
        parent = parent_of[name]
        if parent is None:
            world[name] = (rot, pos)
        else:
            prot, ppos = world[parent]
            world[name] = (prot @ rot, ppos + prot @ pos)
    return world


@pytest.mark.parametrize("case", ["neutral", "rules", "reach"])
def test_a_known_pose_round_trips_through_the_documented_conversion(case: str) -> None:
    """Bundle -> Unity world poses -> ours: every humanoid bone's world rotation and position come back."""
    if case == "neutral":
        frame = _frame()
    elif case == "rules":
        frame = _rules_frame()[1]
    else:
        frame = _frame({"lf_wrist.tz": NEUTRAL["lf_wrist.tz"] + 0.15, "lower_back.rx": 25.0, "head.ry": -15.0})
    pose = rider_pose(frame)
    world = _avatar(_messages(rider_bundle(pose, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), 0.0)))
    rig = rider_rig()
    turns = tpose_turns()
    for name, (unity, _) in HUMANOID.items():
        i = rig.index[name]
        avatar_rot, avatar_pos = world[unity]
        ours = UNITY @ avatar_rot @ UNITY @ _matrix(turns[name]).T  # W = A S^-1, back in our axes
        np.testing.assert_allclose(ours, _matrix(pose.world_rotations[i]), atol=2e-6, err_msg=name)
        np.testing.assert_allclose(UNITY @ avatar_pos, pose.world_positions[i], atol=2e-6, err_msg=name)


T_POSE = {  # Unity axes: the avatar faces +z, its left is -x; the bone -> its child in the T-pose
    "LeftUpperArm": (-1.0, 0.0, 0.0), "LeftLowerArm": (-1.0, 0.0, 0.0), "RightUpperArm": (1.0, 0.0, 0.0),
    "RightLowerArm": (1.0, 0.0, 0.0), "LeftUpperLeg": (0.0, -1.0, 0.0), "LeftLowerLeg": (0.0, -1.0, 0.0),
    "RightUpperLeg": (0.0, -1.0, 0.0), "RightLowerLeg": (0.0, -1.0, 0.0), "Spine": (0.0, 1.0, 0.0),
    "Neck": (0.0, 1.0, 0.0),
}  # fmt: skip
CHILD = {"LeftUpperArm": "lf_forearm", "LeftLowerArm": "lf_hand", "RightUpperArm": "rt_forearm",
         "RightLowerArm": "rt_hand", "LeftUpperLeg": "lf_shin", "LeftLowerLeg": "lf_foot",
         "RightUpperLeg": "rt_shin", "RightLowerLeg": "rt_foot", "Spine": "waist", "Neck": "head"}  # fmt: skip


@pytest.mark.parametrize("case", ["neutral", "rules"])
def test_a_t_pose_avatar_driven_by_the_bundle_points_its_limbs_like_ours(case: str) -> None:
    """A VRM avatar's bones point along T_POSE at rest; driven, they point where our bones point."""
    pose = rider_pose(_frame() if case == "neutral" else _rules_frame()[1])
    world = _avatar(_messages(rider_bundle(pose, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), 0.0)))
    rig = rider_rig()
    by_unity = {unity: name for name, (unity, _) in HUMANOID.items()}
    for unity, rest_dir in T_POSE.items():
        start = pose.world_positions[rig.index[by_unity[unity]]]
        end = pose.world_positions[rig.index[CHILD[unity]]]
        ours = UNITY @ (np.subtract(end, start) / np.linalg.norm(np.subtract(end, start)))
        np.testing.assert_allclose(world[unity][0] @ rest_dir, ours, atol=2e-6, err_msg=unity)


def test_the_horse_at_rest_sends_its_offsets_and_identities() -> None:
    messages = _messages(horse_bundle(horse_pose([0.0] * len(HORSE_NAMES)), HORSE_RIG.names, 0.0))
    for (_, _, args), bone in zip(messages[3:], HORSE_RIG.bones, strict=True):
        np.testing.assert_allclose(args[1:4], UNITY @ np.array(bone.offset), atol=1e-6)
        np.testing.assert_allclose(args[4:8], [0.0, 0.0, 0.0, 1.0], atol=1e-7)
