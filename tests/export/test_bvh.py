"""BVH export, read back by an independent parser (PyPI bvhio): names, frames, world poses."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from riderlive.export import TakePoses
from riderlive.export.axes import positions, rotations
from riderlive.export.bvh import write_bvh
from riderlive.skeleton import quat
from tests.export.conftest import world

bvhio = pytest.importorskip("bvhio")
glm = pytest.importorskip("glm")  # bvhio's maths (PyGLM)


@pytest.fixture(scope="module")
def files(take: TakePoses, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("bvh")
    paths = {}
    for track in (take.horse, take.rider):
        assert track is not None
        paths[track.rig.name] = out / f"canter.{track.rig.name}.bvh"
        with paths[track.rig.name].open("wb") as fh:
            write_bvh(fh, track, take.rate)
    return paths


@pytest.mark.parametrize("skeleton", ["rider", "horse"])
def test_an_independent_reader_sees_the_skeleton_and_its_frames(
    take: TakePoses, files: dict[str, Path], skeleton: str
) -> None:
    track = take.rider if skeleton == "rider" else take.horse
    assert track is not None
    container = bvhio.readAsBvh(str(files[skeleton]))
    assert container.FrameCount == len(take.t) == 120
    assert 1.0 / container.FrameTime == 120.0  # exactly: the frame time is written shortest-exact
    root = bvhio.readAsHierarchy(str(files[skeleton]))
    names = [joint.Name for joint, _, _ in root.layout()]
    if skeleton == "rider":  # the seat point, then the bones, and one branch joint under the hips
        assert names[0] == "rider"
        assert sorted(names[1:]) == sorted([*track.rig.names, "hips_branch"])
    else:  # the horse stays at the world origin: its root bone is the ROOT
        assert names[0] == "root"
        assert sorted(names) == sorted(track.rig.names)


@pytest.mark.parametrize("skeleton", ["rider", "horse"])
def test_every_joint_has_a_bone_length(take: TakePoses, skeleton: str) -> None:
    """The mean of a joint's children's offsets (where Blender aims it) is at least 1 mm from it."""
    from riderlive.export.bvh import layout

    track = take.rider if skeleton == "rider" else take.horse
    assert track is not None
    joints = layout(track)
    for joint in joints:
        if joint.children:
            mean = np.mean([joints[c].offset for c in joint.children], axis=0)
            assert np.linalg.norm(mean) > 0.001, joint.name
    branch = [j for j in joints if j.bone is None and not j.position]
    assert [j.name for j in branch] == (["hips_branch"] if skeleton == "rider" else [])


@pytest.mark.parametrize("rate", [24.0, 25.0, 30.0, 50.0, 60.0, 100.0, 120.0, 240.0, 1000.0])
def test_the_frame_time_reads_back_as_the_exact_rate(rate: float) -> None:
    from riderlive.export.bvh import frame_time

    assert 1.0 / float(frame_time(rate)) == rate


@pytest.mark.parametrize("skeleton", ["rider", "horse"])
@pytest.mark.parametrize("frame", [0, 37, 119])
def test_world_poses_read_back_match_the_solver(
    take: TakePoses, files: dict[str, Path], skeleton: str, frame: int
) -> None:
    """bvhio's own forward kinematics of the file equal our poses in file axes (x left, y up, z forward)."""
    track = take.rider if skeleton == "rider" else take.horse
    assert track is not None
    root = bvhio.readAsHierarchy(str(files[skeleton]))
    root.loadRestPose()
    joints = {joint.Name: joint for joint, _, _ in root.layout()}
    rest = {name: joint.RotationWorld for name, joint in joints.items()}  # bvhio aims its joints along the bones
    root.loadPose(frame)
    ours = world(track.root_position[frame], track.root_rotation[frame], track.poses.world_positions[:, frame])
    expected = positions(ours)
    for b, name in enumerate(track.rig.names):
        p = joints[name].PositionWorld
        np.testing.assert_allclose([p.x, p.y, p.z], expected[b], atol=2e-4, err_msg=name)
        q = joints[name].RotationWorld * glm.inverse(rest[name])  # turn from the rest; glm: w, x, y, z
        world_rot = quat.mul(tuple(track.root_rotation[frame]), tuple(track.poses.world_rotations[b, frame]))  # type: ignore[arg-type]
        want = rotations(np.asarray(world_rot))
        got = np.array([q.x, q.y, q.z, q.w])
        assert min(np.abs(got - want).max(), np.abs(got + want).max()) < 1e-4, name


@pytest.mark.parametrize("skeleton", ["rider", "horse"])
def test_angles_are_unwrapped_over_time(take: TakePoses, skeleton: str) -> None:
    """No channel jumps by more than half a turn between frames (a reader interpolating sees no spin)."""
    from riderlive.export.bvh import motion

    track = take.rider if skeleton == "rider" else take.horse
    assert track is not None
    assert np.abs(np.diff(motion(track), axis=0)).max() <= 180.0 + 1e-9
