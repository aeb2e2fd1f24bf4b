"""The complete skeleton stream: ``pose`` frames carry every rider and horse bone's translation and rotation."""

from __future__ import annotations

import json

import numpy as np
import pytest
from websockets.sync.client import connect

from riderlive.channels import HORSE_NAMES, RIDER_NAMES
from riderlive.realtime.record import RecordLayout
from riderlive.service.codecs import BadFrame, Subscription, decode_subscription
from riderlive.service.hello import pose_floats, units
from riderlive.service.rider_frames import BINARY_HEADER, BONES_HEADER, POSE_HEADER, decode_binary_frame, encode_frame
from riderlive.skeleton import HORSE_RIG, horse_pose, rider_pose, rider_rig
from tests.service.live_server import LiveServer
from tests.service.test_publish import frames
from tests.service.test_skeletons import subscribe

N_RIDER, N_HORSE = len(rider_rig().bones), len(HORSE_RIG.bones)


def test_the_hello_has_machine_readable_units_and_describes_the_pose(server: LiveServer) -> None:
    with connect(server.ws + "/ws/rider") as ws:
        hello = json.loads(ws.recv(timeout=5))
    assert hello["hello_version"] >= 2, "version 2 fields stay in later versions"
    assert (hello["length_unit"], hello["metres_per_length_unit"], hello["rotation_unit"]) == ("m", 1.0, "deg")
    assert hello["time_unit"] == "s"
    assert hello["pose"]["skeletons"] == ["rider", "horse"]
    assert hello["pose"]["layout"] == ["tx", "ty", "tz", "qx", "qy", "qz", "qw"]
    horse = hello["skeletons"]["horse"]["bones"]
    assert [b["name"] for b in horse] == list(HORSE_RIG.names), "every horse bone, hierarchy and bind pose"
    for skeleton in ("rider", "horse"):
        for bone in hello["skeletons"][skeleton]["bones"]:
            assert bone["rest_rotation"] == [0.0, 0.0, 0.0, 1.0]
            assert len(bone["offset"]) == 3 and len(bone["rest_position"]) == 3


@pytest.mark.parametrize("encoding", ["json", "binary"])
def test_pose_frames_carry_both_skeletons_as_the_solver_poses_them(server: LiveServer, encoding: str) -> None:
    with connect(server.ws + "/ws/rider") as ws:
        ws.recv(timeout=5)
        ack = subscribe(ws, pose=True, horse_channels=list(HORSE_NAMES), encoding=encoding, decimation=2)
        assert ack["pose"] == ["rider", "horse"]
        got = frames(ws, 20)[-10:]
    for f in got:
        assert set(f["pose"]) == {"rider", "horse"}
        rider = np.array(f["pose"]["rider"]).reshape(N_RIDER, 7)
        horse = np.array(f["pose"]["horse"]).reshape(N_HORSE, 7)
        np.testing.assert_allclose(rider.ravel(), pose_floats(rider_pose(f["values"][: len(RIDER_NAMES)])), atol=1e-12)
        np.testing.assert_allclose(horse.ravel(), pose_floats(horse_pose(f["horse"])), atol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(rider[:, 3:], axis=1), 1.0, atol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(horse[:, 3:], axis=1), 1.0, atol=1e-12)
        # The hips translate with the seat: the stream carries it, no reconstruction needed.
        values = dict(zip(RIDER_NAMES, f["values"], strict=False))
        neutral = rider_rig().neutral
        seat = (values["cog.tx"] - neutral["cog.tx"], values["cog.ty"] - neutral["cog.ty"], 0.0)
        np.testing.assert_allclose(rider[0, :3], np.add(rider_rig().bones[0].offset, seat), atol=1e-12)


def test_binary_pose_follows_the_bones_block_and_decodes_back() -> None:
    record = np.arange(RecordLayout.rider.stop, dtype=np.float64)
    record[RecordLayout.driver.start] = 1.0
    bones = np.linspace(-1.0, 1.0, 4 * N_RIDER)
    pose = {"rider": np.linspace(0.0, 1.0, 7 * N_RIDER), "horse": np.linspace(2.0, 3.0, 7 * N_HORSE)}
    for sub, extra in (
        (Subscription(encoding="binary", pose=("rider", "horse"), bones=True, horse=(1,)), BONES_HEADER.size),
        (Subscription(encoding="binary", pose=("horse",)), 0),
    ):
        data = encode_frame(sub, record, bones, pose)
        assert isinstance(data, bytes)
        assert int.from_bytes(data[4:6], "little") == BINARY_HEADER.size + extra + POSE_HEADER.size
        decoded = decode_binary_frame(data)
        assert decoded["values"] == record[RecordLayout.rider.start :].tolist()
        assert decoded.get("bones") == (bones.tolist() if sub.bones else None)
        assert decoded["pose"] == {name: pose[name].tolist() for name in sub.pose}
        assert json.loads(encode_frame(Subscription(pose=sub.pose), record, None, pose))["pose"] == {
            name: pose[name].tolist() for name in sub.pose
        }


@pytest.mark.parametrize(
    ("value", "reason"),
    [("rider", "wrong_type"), (["rider", 3], "wrong_type"), (["saddle"], "unknown_skeleton"), (1, "wrong_type")],
)
def test_a_bad_pose_request_is_refused(value: object, reason: str) -> None:
    with pytest.raises(BadFrame) as info:
        decode_subscription({"pose": value}, Subscription(), 120.0)
    assert info.value.reason == reason
    assert decode_subscription({"pose": ["horse", "rider"]}, Subscription(), 120.0).pose == ("rider", "horse")
    assert decode_subscription({"pose": False}, Subscription(pose=("rider",)), 120.0).pose == ()


def test_length_units_are_symbols() -> None:
    assert units(25.0) == ("m", 1.0)
    assert units(0.25) == ("cm", 0.01)
    assert units(0.025) == ("mm", 0.001)
    assert units(10.0) == ("0.4 m", 0.4)


def test_the_protocol_doc_states_the_rigs_axis_mapping() -> None:
    """docs/protocol.md's channel -> bone table matches the rider rig's drives, sign by sign."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / "docs" / "protocol.md").read_text()
    section = text.split("### Channels and bones: the axis mapping", 1)[1].split("\n### ", 1)[0]
    drives = {d.channel: d for d in (*rider_rig().rotations, *rider_rig().translations)}
    seen = set()
    for line in section.splitlines():
        if not line.startswith("| `"):
            continue
        cells = [c.strip() for c in line.strip("|").split("|")]
        channels = [c.strip(" `") for c in cells[0].split(",")]
        bones = [b.strip() for b in cells[1].split(",")]
        axes = [a.strip() for a in cells[2].split(",")]
        signs = [float(s) for s in cells[3].split(",")]
        for k, channel in enumerate(channels):
            drive = drives[channel]
            assert drive.bone == bones[min(k, len(bones) - 1)], channel
            axis = "xyz"[list(drive.axis).index(1.0)]
            assert axis == axes[min(k, len(axes) - 1)], channel
            assert drive.sign == signs[min(k, len(signs) - 1)], channel
            seen.add(channel)
    assert seen == set(drives), f"undocumented: {sorted(set(drives) - seen)}"
