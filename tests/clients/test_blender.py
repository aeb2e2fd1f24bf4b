"""The Blender add-on, run in real Blender (PyPI ``bpy`` in ``.venv/blender``, installed by install.sh).

Blender drives the add-on's armatures from a live service for 2 s; every frame it
applied is compared, bone by bone, with the solver on that frame's streamed channels:
Blender's own evaluation of the armature (world rotation and head of each pose bone)
must equal ``rider_pose`` / ``horse_pose`` converted to Blender's axes. Then it imports
an exported take and its bone heads are compared with the take's poses.
"""

from __future__ import annotations

import json
import os
import subprocess
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from riderlive.channels import RIDER_NAMES
from riderlive.export import load_take
from riderlive.export.gltf import write_glb
from riderlive.skeleton import HORSE_RIG, horse_pose, quat, rider_pose, rider_rig
from tests.export.conftest import write_take
from tests.service.conftest import BASE_CONFIG
from tests.service.live_server import LiveServer

ROOT = Path(__file__).resolve().parents[2]
BLENDER_PYTHON = ROOT / ".venv" / "blender" / "bin" / "python"
TO_BLENDER = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])

pytestmark = pytest.mark.skipif(
    not BLENDER_PYTHON.exists(), reason="Blender as a module (PyPI bpy) is not installed in .venv/blender (install.sh)"
)


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """One service for both Blender runs: each only reads ``/ws/rider``."""
    live = LiveServer(BASE_CONFIG, tmp_path_factory.mktemp("blender"))
    yield live
    live.stop()


def _matrix(q: np.ndarray) -> np.ndarray:
    """x y z w -> 3x3."""
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _wxyz(q: list[float]) -> np.ndarray:
    return _matrix(np.array([q[1], q[2], q[3], q[0]]))


def _blender(rotation: np.ndarray) -> np.ndarray:
    return TO_BLENDER @ rotation @ TO_BLENDER.T


def _run_blender(args: list[str], out: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT / "clients" / "blender"))
    proc = subprocess.run(
        [str(BLENDER_PYTHON), str(Path(__file__).with_name("blender_drive.py")), *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return dict(json.loads(out.read_text()))


def test_blender_drives_armatures_from_the_stream_and_imports_a_take(server: LiveServer, tmp_path: Path) -> None:
    take_file = write_take(tmp_path, "canter", seconds=0.5)
    take = load_take(take_file)
    glb = tmp_path / "canter.glb"
    with glb.open("wb") as fh:
        write_glb(fh, take)
    out = tmp_path / "blender.json"
    result = _run_blender([server.ws + "/ws/rider", "2.0", str(out), str(glb), "1", "31", "60"], out)
    assert result["error"] is None
    samples, applied = result["samples"], result["applied"]
    # It drove for the whole 2 s of stream, newest frames only (how many depends on the machine's load).
    assert applied[-1]["t"] - applied[0]["t"] >= 1.5
    assert [a["seq"] for a in applied] == sorted({a["seq"] for a in applied})
    assert len(samples) >= 3
    rig, saddle = rider_rig(), HORSE_RIG.index["saddle"]
    for sample in samples:
        rider = rider_pose(sample["values"][: len(RIDER_NAMES)])
        horse = horse_pose(sample["horse"])
        seat_rot, seat_pos = horse.world_rotations[saddle], horse.world_positions[saddle]
        for skeleton, pose, bones in (("rider", rider, rig.names), ("horse", horse, HORSE_RIG.names)):
            got = sample[f"{skeleton}_bones"]
            for i, name in enumerate(bones):
                world_rot = pose.world_rotations[i]
                world_pos = pose.world_positions[i]
                if skeleton == "rider":
                    world_rot = quat.mul(seat_rot, world_rot)
                    world_pos = quat.add(seat_pos, quat.rotate(seat_rot, world_pos))
                expected = _blender(_matrix(np.array(world_rot))) @ _wxyz(result["rest"][skeleton][name])
                np.testing.assert_allclose(_wxyz(got[name]["rotation"]), expected, atol=1e-5, err_msg=name)
                # Blender keeps matrices in float32: the horse may have travelled 100 m by now.
                np.testing.assert_allclose(got[name]["head"], TO_BLENDER @ np.array(world_pos), rtol=1e-6, atol=1e-5)
    assert result["fps"] == 120
    for frame_text, objects in result["take"].items():
        k = int(frame_text) - 1
        for track in (take.rider, take.horse):
            assert track is not None
            got = objects[track.rig.name]
            for i, name in enumerate(track.rig.names):
                q = track.root_rotation[k]
                world = track.root_position[k] + np.array(
                    quat.rotate(tuple(q), tuple(track.poses.world_positions[i, k]))
                )  # type: ignore[arg-type]
                np.testing.assert_allclose(got[name]["head"], TO_BLENDER @ world, atol=1e-4, err_msg=name)


def test_background_blender_drives_with_the_frames_step(server: LiveServer, tmp_path: Path) -> None:
    """``blender -b`` never fires the live mode's timers: ``riderlive_blender.drive`` steps it (N new
    frames, keyed), as a script or a render farm would."""
    out = tmp_path / "drive.json"
    script = (
        "import json, sys, bpy, riderlive_blender as r\n"
        "bpy.ops.wm.read_factory_settings(use_empty=True)\n"
        "n = r.drive(sys.argv[1], frames=30, key=True)\n"
        "rider = bpy.data.objects['riderlive_rider']\n"
        "action = rider.animation_data.action\n"
        "curves = list(getattr(action, 'fcurves', []) or [c for l in action.layers for s in l.strips"
        " for b in s.channelbags for c in b.fcurves])\n"
        "json.dump({'applied': n, 'keys': max(len(c.keyframe_points) for c in curves)}, open(sys.argv[2], 'w'))\n"
    )
    env = dict(os.environ, PYTHONPATH=str(ROOT / "clients" / "blender"))
    proc = subprocess.run(
        [str(BLENDER_PYTHON), "-c", script, server.ws + "/ws/rider", str(out)],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert json.loads(out.read_text()) == {"applied": 30, "keys": 30}
