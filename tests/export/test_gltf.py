"""glTF export: the Khronos validator (npm gltf-validator) and pygltflib read what we write."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from riderlive.export import TakePoses
from riderlive.export.axes import positions, rotations
from riderlive.export.gltf import write_glb
from riderlive.skeleton import quat
from tests.export.conftest import world

pygltflib = pytest.importorskip("pygltflib")
ROOT = Path(__file__).resolve().parents[2]
VALIDATOR = ROOT / ".venv" / "npm" / "node_modules"


@pytest.fixture(scope="module")
def glb(take: TakePoses, tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("gltf") / "canter.glb"
    with path.open("wb") as fh:
        write_glb(fh, take)
    return path


@pytest.mark.skipif(
    shutil.which("node") is None or not (VALIDATOR / "gltf-validator").is_dir(),
    reason="needs node and npm gltf-validator (install.sh installs it into .venv/npm)",
)
def test_the_khronos_validator_finds_no_error_or_warning(glb: Path) -> None:
    out = subprocess.run(
        ["node", str(Path(__file__).with_name("validate_gltf.mjs")), str(glb)],
        env={"VALIDATOR_DIR": str(VALIDATOR), "PATH": "/usr/bin:/bin"},
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    issues = json.loads(out.stdout)
    assert issues["numErrors"] == 0, issues["messages"]
    assert issues["numWarnings"] == 0, issues["messages"]
    # Only "skin unused" notes: the file has armatures and no mesh.
    assert {m["code"] for m in issues["messages"]} <= {"UNUSED_OBJECT"}


def _read(gltf: pygltflib.GLTF2, index: int, blob: bytes) -> np.ndarray:
    accessor = gltf.accessors[index]
    view = gltf.bufferViews[accessor.bufferView]
    width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[accessor.type]
    start = view.byteOffset + (accessor.byteOffset or 0)
    data = np.frombuffer(blob, dtype="<f4", count=accessor.count * width, offset=start)
    return data.reshape(accessor.count, width)


def _matrix(q: np.ndarray) -> np.ndarray:
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


@pytest.mark.parametrize("frame", [0, 61, 119])
def test_node_animation_read_by_pygltflib_poses_both_skeletons_like_the_solver(
    take: TakePoses, glb: Path, frame: int
) -> None:
    """Forward kinematics written here from the file's nodes and samplers alone (matrices, not our quaternion code)."""
    gltf = pygltflib.GLTF2().load(str(glb))
    assert gltf.asset.version == "2.0"
    animation = gltf.animations[0]
    blob = gltf.binary_blob()
    times = _read(gltf, animation.samplers[0].input, blob)[:, 0]
    np.testing.assert_allclose(times, take.t, atol=1e-5)
    local = {i: (np.array(n.translation or [0, 0, 0], float), np.eye(3)) for i, n in enumerate(gltf.nodes)}
    for ch in animation.channels:
        values = _read(gltf, animation.samplers[ch.sampler].output, blob)[frame].astype(float)
        t, r = local[ch.target.node]
        if ch.target.path == "rotation":
            assert abs(np.linalg.norm(values) - 1.0) < 1e-6
            local[ch.target.node] = (t, _matrix(values))
        else:
            local[ch.target.node] = (values, r)
    parent = {c: i for i, n in enumerate(gltf.nodes) for c in (n.children or [])}
    world_pos: dict[int, np.ndarray] = {}
    world_rot: dict[int, np.ndarray] = {}
    for i in range(len(gltf.nodes)):  # parents come first
        t, r = local[i]
        p = parent.get(i)
        world_pos[i] = t if p is None else world_pos[p] + world_rot[p] @ t
        world_rot[i] = r if p is None else world_rot[p] @ r
    for skin, track in zip(gltf.skins, (take.horse, take.rider), strict=True):
        assert track is not None
        assert skin.name == track.rig.name
        names = [gltf.nodes[j].name for j in skin.joints]
        assert names == [track.rig.name, *track.rig.names]
        ours = positions(
            world(track.root_position[frame], track.root_rotation[frame], track.poses.world_positions[:, frame])
        )
        got = np.array([world_pos[j] for j in skin.joints[1:]])
        np.testing.assert_allclose(got, ours, atol=1e-5)
        for b, j in enumerate(skin.joints[1:]):
            q = quat.mul(tuple(track.root_rotation[frame]), tuple(track.poses.world_rotations[b, frame]))  # type: ignore[arg-type]
            np.testing.assert_allclose(world_rot[j], _matrix(rotations(np.asarray(q))), atol=1e-5)


def test_each_skeleton_hangs_under_its_own_armature_node_outside_its_skin(take: TakePoses, glb: Path) -> None:
    """What makes Blender's importer build one armature per skeleton: a static non-joint parent per skin."""
    gltf = pygltflib.GLTF2().load(str(glb))
    scene = [gltf.nodes[i] for i in gltf.scenes[0].nodes]
    assert [n.name for n in scene] == ["horse_armature", "rider_armature"]
    for node, skin in zip(scene, gltf.skins, strict=True):
        assert node.children == [skin.joints[0]] == [skin.skeleton]
        assert node.translation is None and node.rotation is None and node.matrix is None
        assert skin.joints[0] not in gltf.scenes[0].nodes
    animated = {ch.target.node for ch in gltf.animations[0].channels}
    assert not animated & set(gltf.scenes[0].nodes)


def test_file_axes_are_a_proper_rotation_of_ours() -> None:
    """x left, y up, z forward: a rotated vector maps the same whichever way round."""
    rng = np.random.default_rng(1)
    for _ in range(20):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        v = rng.normal(size=3)
        assert np.allclose(rotations(q), quat.to_gltf(tuple(q)))  # type: ignore[arg-type]
        turned = positions(np.asarray(quat.rotate(tuple(q), tuple(v))))  # type: ignore[arg-type]
        assert np.allclose(turned, quat.rotate(tuple(rotations(q)), tuple(positions(v))))  # type: ignore[arg-type]
    assert np.allclose(positions(np.array([1.0, 0.0, 0.0])), [0.0, 0.0, 1.0])  # forward is +z
    assert np.allclose(positions(np.array([0.0, 0.0, 1.0])), [-1.0, 0.0, 0.0])  # the right is -x
