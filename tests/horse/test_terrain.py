"""The procedural horse on sloping ground (thesis section 10): placement, pitch, C1, live = batch."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from riderlive.channels import HORSE_INDEX
from riderlive.configfile import ConfigError
from riderlive.horse import ProceduralHorse, ShotScript, TerrainConfig, generate
from riderlive.horse.curves import ARRAY, SCALAR
from riderlive.horse.script import load_script
from riderlive.horse.terrain import FLAT, HOOF_BASE, MAX_SLOPE, TRANSITION, Terrain, join
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
    # one source for both (floats and arrays): bit for bit where NumPy's primitives are
    # libm's; on AVX-512 NumPy's own exp/atan2/tan differ from libm's by an ulp (docs/testing.md)
    np.testing.assert_allclose(live, batch, rtol=1e-13, atol=1e-13)


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


# -- changing the ground under a running horse (the live service's PUT /api/source) ------------

slopes = st.floats(-MAX_SLOPE, MAX_SLOPE, allow_nan=False)
grounds = st.one_of(
    st.none(),
    slopes.map(lambda s: TerrainConfig(slope=s).terrain()),
    st.lists(st.tuples(st.floats(0.05, 20.0), slopes), min_size=1, max_size=6).map(
        lambda steps: TerrainConfig(
            profile=[(float(d), s) for d, s in zip(np.cumsum([0.0] + [d for d, _ in steps[1:]]), [s for _, s in steps])]
        ).terrain()
    ),
)


def _xy(terrain: Terrain | None, s: float) -> tuple[float, float]:
    return (s, 0.0) if terrain is None else terrain.position(s, SCALAR)


@settings(max_examples=200, deadline=None)
@given(grounds, grounds, st.floats(0.0, 60.0), st.floats(0.0, 1.0))
def test_a_joined_ground_keeps_the_old_under_the_horse_and_eases_into_the_new(
    old: Terrain | None, new: Terrain | None, at: float, f: float
) -> None:
    joined, start = join(old, new, at)
    if old is None and new is None:
        assert (joined, start) == (None, 0.0)
        return
    assert joined is not None
    fore = at + HOOF_BASE / 2
    assert start == pytest.approx(fore + TRANSITION)
    before, after = FLAT if old is None else old, FLAT if new is None else new
    for s in np.linspace(at - HOOF_BASE / 2, fore, 9):  # all the horse at `at` stands on or pitches by
        np.testing.assert_allclose(joined.position(float(s), SCALAR), _xy(old, float(s)), rtol=0.0, atol=1e-9)
    np.testing.assert_allclose(joined.place(at, SCALAR), before.place(at, SCALAR), rtol=0.0, atol=1e-9)
    # the slope: the old one's up to the fore hooves, linear over TRANSITION, then the new ground's
    a, b = before.slope_at(fore), after.slope_at(0.0)
    assert joined.slope_at(fore) == pytest.approx(a, abs=1e-9)
    assert joined.slope_at(fore + f * TRANSITION) == pytest.approx(a + f * (b - a), abs=1e-9)
    x0, y0 = joined.position(start, SCALAR)
    for u in (0.0, 0.3, 7.0, 25.0, 80.0):
        assert joined.slope_at(start + u) == pytest.approx(after.slope_at(u), abs=1e-9)
        x, y = joined.position(start + u, SCALAR)
        ux, uy = after.position(u, SCALAR)
        vx, vy = after.position(0.0, SCALAR)
        np.testing.assert_allclose((x - x0, y - y0), (ux - vx, uy - vy), rtol=0.0, atol=1e-9)


def test_changes_do_not_pile_up_knots() -> None:
    ground: Terrain | None = None
    for i in range(200):
        ground, _ = join(ground, TerrainConfig(slope=(-1) ** i * 10.0).terrain(), 7.0 * i)
        assert ground is not None and len(ground.distances) <= 5
    # after 200 changes 7 m apart the horse stands on the last ramp's start: still exact
    assert ground.slope_at(7.0 * 199 + HOOF_BASE / 2) == pytest.approx(10.0 * (-1) ** 198, abs=1e-9)


def test_a_running_horse_changes_ground_without_a_jump() -> None:
    """Flat, then a 10 degree hill at t = 2 s: position and pitch stay C1, the hill is reached."""
    rate, speed = 120.0, 4.0
    horse, flat = ProceduralHorse("trot", speed), ProceduralHorse("trot", speed)
    times = np.arange(0.0, 6.0, 1.0 / rate)
    frames, flats, change = [], [], int(2.0 * rate)
    for i, t in enumerate(times):
        if i == change:
            start = horse.set_terrain(TerrainConfig(slope=10.0).terrain())
        frames.append(horse.sample(float(t)))
        flats.append(flat.sample(float(t)))
    v = np.array(frames)
    np.testing.assert_array_equal(v[:change], np.array(flats)[:change])
    s = col(np.array(flats), "root.tx")  # the distance along the ground
    assert start == pytest.approx(s[change - 1] + HOOF_BASE / 2 + TRANSITION)
    step = speed / rate
    moved = np.hypot(np.diff(col(v, "root.tx")), np.diff(col(v, "root.ty")))
    np.testing.assert_allclose(moved, np.diff(s), rtol=1e-6)  # along the ground: no jump in position
    pitch = col(v, "ground.rz")
    # the slope rises at 10 deg / TRANSITION: the chord's pitch at most that per metre,
    # and its rate of change continuous (second difference of order step^2, a kink would be ~ step)
    assert np.abs(np.diff(pitch)).max() <= 10.0 / TRANSITION * step * (1 + 1e-6)
    assert np.abs(np.diff(pitch, 2)).max() <= 2 * 10.0 / TRANSITION / HOOF_BASE * step**2 * (1 + 1e-6)
    on_hill = s >= start + HOOF_BASE / 2
    assert on_hill.sum() > rate  # a second of it
    np.testing.assert_allclose(pitch[on_hill], 10.0, atol=1e-9)
    rise = np.diff(col(v, "root.ty")[on_hill]) / np.diff(s[on_hill])
    np.testing.assert_allclose(rise, math.sin(math.radians(10.0)), atol=1e-9)
    np.testing.assert_allclose(pitch[:change], 0.0, atol=0.0)


def test_a_ground_given_before_the_first_sample_starts_there() -> None:
    horse = ProceduralHorse("walk")
    assert horse.set_terrain(TerrainConfig(profile=PROFILE).terrain()) == 0.0
    built = ProceduralHorse("walk", terrain=TerrainConfig(profile=PROFILE).terrain())
    assert [horse.sample(i / 60.0) for i in range(300)] == [built.sample(i / 60.0) for i in range(300)]
