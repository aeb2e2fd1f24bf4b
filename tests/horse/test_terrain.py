"""The procedural horse on sloping ground (thesis section 10): placement, pitch, C1, live = batch."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from riderlive.channels import HORSE_INDEX
from riderlive.configfile import ConfigError
from riderlive.horse import ProceduralHorse, ShotScript, TerrainConfig, generate
from riderlive.horse.curves import ARRAY
from riderlive.horse.script import load_script
from riderlive.horse.terrain import HOOF_BASE
from riderlive.skeleton import horse_pose
from riderlive.skeleton.horse import HORSE_RIG

PROFILE = [[0.0, 0.0], [4.0, 12.0], [12.0, 12.0], [16.0, -8.0]]
BODY = [n for n in HORSE_INDEX if not n.startswith(("root.", "ground.")) and n != "rearPivot.rz"]


def take(terrain: dict[str, object] | None, rate: float = 120.0, seconds: float = 6.0) -> np.ndarray:
    script = ShotScript.model_validate({"terrain": terrain, "segment": [{"gait": "trot", "seconds": seconds}]})
    return generate(script, rate).values


def col(values: np.ndarray, name: str) -> np.ndarray:
    return values[:, HORSE_INDEX[name]]


def test_a_constant_slope_pitches_and_lifts_the_horse() -> None:
    flat, hill = take(None), take({"slope": 10.0})
    s = col(flat, "root.tx")  # distance along the ground
    theta = math.radians(10.0)
    np.testing.assert_allclose(col(hill, "root.tx"), s * math.cos(theta), atol=1e-9)
    np.testing.assert_allclose(col(hill, "root.ty"), s * math.sin(theta), atol=1e-9)
    np.testing.assert_allclose(col(hill, "ground.ty"), col(hill, "root.ty"), atol=0.0)
    np.testing.assert_allclose(col(hill, "ground.rz"), 10.0, atol=1e-9)
    np.testing.assert_allclose(col(hill, "rearPivot.rz"), col(flat, "rearPivot.rz") + 10.0, atol=1e-9)
    for name in BODY:  # hooves above the local ground, hips and back as on the flat
        np.testing.assert_array_equal(col(hill, name), col(flat, name), err_msg=name)
    for name in ("ground.rz", "ground.ty", "root.ty"):
        assert not col(flat, name).any()


def test_the_pitch_follows_the_chord_under_the_hooves_and_stays_c1() -> None:
    terrain = TerrainConfig(profile=PROFILE).terrain()
    assert terrain is not None
    s = np.linspace(-2.0, 22.0, 2001)
    x, y, pitch = terrain.place(s, ARRAY)
    x0, y0 = terrain.position(s - HOOF_BASE / 2, ARRAY)
    x1, y1 = terrain.position(s + HOOF_BASE / 2, ARRAY)
    np.testing.assert_allclose(np.tan(np.radians(pitch)), (y1 - y0) / (x1 - x0), atol=1e-12)
    np.testing.assert_allclose(np.hypot(np.diff(x), np.diff(y)), np.diff(s), rtol=1e-6)  # s is along the ground
    assert pitch.max() == pytest.approx(12.0, abs=1e-9) and pitch.min() == pytest.approx(-8.0, abs=1e-9)
    # C1 in time: the largest second difference / dt^2 stays bounded as the rate rises (a kink grows 4x)
    for name in ("rearPivot.rz", "root.ty", "ground.rz"):
        curv = [
            np.abs(np.diff(col(take({"profile": PROFILE}, rate, 8.0), name), 2)).max() * rate**2
            for rate in (1000.0, 4000.0)
        ]
        assert curv[1] < 1.5 * curv[0], (name, curv)


def test_live_and_batch_agree_on_a_profile() -> None:
    terrain = TerrainConfig(profile=PROFILE).terrain()
    horse = ProceduralHorse("trot", terrain=terrain)
    batch = take({"profile": PROFILE})
    live = np.array([horse.sample(i / 120.0) for i in range(len(batch))])
    np.testing.assert_array_equal(live, batch)


def test_the_skeleton_stands_on_the_slope() -> None:
    """A standing horse on a 10 degree slope: all four hooves on the ground line through the root."""
    script = ShotScript.model_validate({"terrain": {"slope": 10.0}, "segment": [{"gait": "halt", "seconds": 1.0}]})
    frame = generate(script, 10.0).values[-1]
    pose = horse_pose(dict(zip(HORSE_INDEX, frame.tolist(), strict=True)))
    root = np.array(pose.world_positions[HORSE_RIG.index["root"]])
    for hoof in ("lf", "rf", "lb", "rb"):
        p = np.array(pose.world_positions[HORSE_RIG.index[f"{hoof}Hoof"]]) - root
        flat = np.array(HORSE_RIG.rest_world()[HORSE_RIG.index[f"{hoof}Hoof"]])
        assert p[1] == pytest.approx(
            math.tan(math.radians(10.0)) * p[0] + flat[1] / math.cos(math.radians(10.0)), abs=1e-6
        )


@pytest.mark.parametrize(
    ("text", "key", "message"),
    [
        ("slope = 40", "terrain.slope", "less than or equal to 30"),
        ("slope = nan", "terrain.slope", "finite"),
        ("profile = [[0, 0], [5, 35]]", "terrain.profile", "knot 1: slope must be within -30-30 deg"),
        ("profile = [[0, 0], [0, 5]]", "terrain.profile", "knot 1: distances must increase strictly"),
        ("profile = [[-1, 0]]", "terrain.profile", "knot 0: distance must be within 0-100000 m"),
        ("slope = 5\nprofile = [[0, 5]]", "terrain", "exactly one of 'slope'"),
        ("height = 5", "terrain.height", "unknown key"),
    ],
)
def test_bad_terrain_names_file_key_and_range(tmp_path: Path, text: str, key: str, message: str) -> None:
    path = tmp_path / "hill.toml"
    path.write_text(f'[terrain]\n{text}\n\n[[segment]]\ngait = "walk"\nseconds = 1\n')
    with pytest.raises(ConfigError, match=message) as err:
        load_script(path)
    assert str(err.value).startswith(f"{path}: {key}:")
