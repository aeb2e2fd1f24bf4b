"""Blender's own importers (PyPI ``bpy`` in ``.venv/blender``) on the files ``riderlive export`` writes.

A combined horse + rider take: the glTF importer, with each bone-orientation option, makes
two armatures (one per skeleton, each bone name once, no ``.001``), every bone's head where
our solver puts it, and no object besides them but Blender's own bone display shape (the
BLENDER option's Icosphere, in its hidden ``glTF_not_exported`` collection). The BVH importer
loads both files without a "zero length node" warning, sets the scene to exactly the take's
120 fps, and places every joint as the solver does.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from riderlive.export import load_take
from riderlive.export.bvh import write_bvh
from riderlive.export.gltf import ARMATURE_SUFFIX, write_glb
from riderlive.export.take import SkeletonTrack
from riderlive.skeleton import quat
from tests.export.conftest import write_take

ROOT = Path(__file__).resolve().parents[2]
BLENDER_PYTHON = ROOT / ".venv" / "blender" / "bin" / "python"
TO_BLENDER = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
"""Skeleton axes (x forward, y up, z right) to Blender's (z up, the characters face -y)."""
FRAMES = [0, 30, 55]
"""Take frames (120 fps) that fall on whole frames of the glTF import's 24 fps scene too."""
SHAPES = "glTF_not_exported"

pytestmark = pytest.mark.skipif(
    not BLENDER_PYTHON.exists(), reason="Blender as a module (PyPI bpy) is not installed in .venv/blender (install.sh)"
)


@pytest.fixture(scope="module")
def imported(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, str, dict[str, SkeletonTrack]]:
    tmp = tmp_path_factory.mktemp("blender_import")
    take = load_take(write_take(tmp, "canter", seconds=0.5))
    assert take.rate == 120.0 and take.horse is not None and take.rider is not None
    glb = tmp / "canter.glb"
    with glb.open("wb") as fh:
        write_glb(fh, take)
    bvh = {}
    for track in (take.rider, take.horse):
        bvh[track.rig.name] = tmp / f"canter.{track.rig.name}.bvh"
        with bvh[track.rig.name].open("wb") as fh:
            write_bvh(fh, track, take.rate)
    out = tmp / "blender.json"
    proc = subprocess.run(
        [
            str(BLENDER_PYTHON),
            str(Path(__file__).with_name("blender_import.py")),
            *map(str, (out, glb, bvh["rider"], bvh["horse"], *FRAMES)),
        ],
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(out.read_text()), proc.stdout, {"rider": take.rider, "horse": take.horse}


def _world(track: SkeletonTrack, k: int) -> dict[str, np.ndarray]:
    """Every bone's world head (and the skeleton's root), Blender axes."""
    q = tuple(track.root_rotation[k])
    out = {track.rig.name: TO_BLENDER @ track.root_position[k]}
    for i, name in enumerate(track.rig.names):
        p = track.root_position[k] + np.array(quat.rotate(q, tuple(track.poses.world_positions[i, k])))  # type: ignore[arg-type]
        out[name] = TO_BLENDER @ p
    return out


@pytest.mark.parametrize("heuristic", ["BLENDER", "TEMPERANCE", "FORTUNE"])
def test_gltf_imports_as_two_armatures_each_skeleton_in_place(
    imported: tuple[dict, str, dict[str, SkeletonTrack]], heuristic: str
) -> None:
    result, _, tracks = imported
    entry = result["gltf"][heuristic]
    assert sorted(entry["armatures"]) == sorted(f"{name}{ARMATURE_SUFFIX}" for name in tracks)
    for obj in entry["objects"]:
        if obj["type"] != "ARMATURE":  # Blender's bone display shape, nothing from the file
            assert heuristic == "BLENDER" and obj["collections"] == [SHAPES] and obj["shape"], obj
    for name, track in tracks.items():
        arm = entry["armatures"][f"{name}{ARMATURE_SUFFIX}"]
        assert sorted(arm["bones"]) == sorted([name, *track.rig.names])  # each once: no "hips.001"
        for k in FRAMES:
            got = arm["heads"][str(k)]
            for bone, want in _world(track, k).items():
                np.testing.assert_allclose(got[bone], want, atol=1e-4, err_msg=f"{heuristic} {name} {bone} {k}")


def test_bvh_imports_without_warnings_at_the_exact_rate(imported: tuple[dict, str, dict[str, SkeletonTrack]]) -> None:
    result, stdout, tracks = imported
    log = stdout.split("RIDERLIVE-BVH-START", 1)[1].split("RIDERLIVE-BVH-END", 1)[0]
    assert "zero length" not in log and "warning" not in log.lower(), log
    bvh = result["bvh"]
    assert (bvh["fps"], bvh["fps_base"]) == (120, 1.0)
    assert [o["type"] for o in bvh["objects"]] == ["ARMATURE", "ARMATURE"]
    for name, track in tracks.items():
        arm = bvh["armatures"][f"canter.{name}"]
        assert len(arm["bones"]) == len(set(arm["bones"]))
        assert set(track.rig.names) <= set(arm["bones"])
        for k in FRAMES:
            got = arm["heads"][str(k)]
            for bone, want in _world(track, k).items():
                if bone in got:  # the horse's file has its root bone as ROOT (the world origin is no bone)
                    np.testing.assert_allclose(got[bone], want, atol=2e-4, err_msg=f"bvh {name} {bone} {k}")
