"""A rider from mocap: riderlive's own BVH comes back as the rider channels; other skeletons' axes,
units and Euler orders convert; a skeleton the map does not describe is refused."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from riderlive.cli import main
from riderlive.export.bvh import hierarchy, motion
from riderlive.export.take import load_take
from riderlive.fit.bonemap import UNITS, BoneMap, load_bonemap, rider_channels, shipped_bonemaps
from riderlive.fit.bvh import BvhTake, read_bvh
from riderlive.fit.problem import FitInputError
from riderlive.framefile import read_frames, write_frames
from riderlive.frameunits import METRES, record_scale
from riderlive.rules.params import load_preset
from tests.fit.takes import horse_table, rider_table

UNREAD = {"lf_knee.tz", "rt_knee.tz", "lf_knee.ty", "rt_knee.ty", "hair.up", "hair.side", "cloth.up", "cloth.side"}
"""Rider channels no pose determines (poles: only their plane shows; attributes)."""


@pytest.fixture(scope="module")
def baked(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A rider take (english, the jump shot: every clamp at work) as a frame file."""
    path = tmp_path_factory.mktemp("bvh") / "jump_rider.csv"
    write_frames(str(path), rider_table("jump", load_preset("english")))
    return path


def full_precision_bvh(rider_csv: Path, out: Path) -> Path:
    """``riderlive export``'s BVH of ``rider_csv`` (its hierarchy and motion), values unrounded."""
    track = load_take(rider_csv).rider
    assert track is not None
    values = motion(track)
    lines = [hierarchy(track), "MOTION", f"Frames: {len(values)}", f"Frame Time: {1 / 120:.10f}"]
    lines += [" ".join(repr(float(v)) for v in row) for row in values]
    out.write_text("\n".join(lines) + "\n")
    return out


def test_riderlives_own_bvh_comes_back_exactly(baked: Path, tmp_path: Path) -> None:
    take = read_bvh(str(full_precision_bvh(baked, tmp_path / "jump.rider.bvh")))
    channels = rider_channels(take, load_bonemap("riderlive"))
    truth = read_frames(str(baked))
    assert set(channels) == set(truth.names) - UNREAD
    for name, values in channels.items():
        readable = np.isfinite(values)  # a straight limb: the IK stopped short of its target
        assert readable.mean() >= 0.97 if "wrist" in name else readable.all(), name
        np.testing.assert_allclose(values[readable], truth.column(name)[readable], rtol=0, atol=1e-6, err_msg=name)


def test_the_exported_file_comes_back_to_its_rounding(baked: Path, tmp_path: Path) -> None:
    """``riderlive export`` rounds to 1e-5 (m, deg); through the IK chains that stays under 1e-4."""
    assert main(["export", str(baked), "--format", "bvh", "-o", str(tmp_path / "jump")]) == 0
    channels = rider_channels(read_bvh(str(tmp_path / "jump.rider.bvh")), load_bonemap("riderlive"))
    truth = read_frames(str(baked))
    for name, values in channels.items():
        readable = np.isfinite(values)
        np.testing.assert_allclose(values[readable], truth.column(name)[readable], rtol=0, atol=1e-4, err_msg=name)


def rewrite(take: BvhTake, bonemap: BoneMap, order: str) -> str:
    """``take`` (riderlive's axes and metres) as a BVH in ``bonemap``'s joint names, unit and axes, every
    rotation channel in Euler ``order`` (e.g. "ZXY": Zrotation Xrotation Yrotation)."""
    a = load_bonemap("riderlive").axes.matrix()  # rider from riderlive file
    b = bonemap.axes.matrix()  # rider from the target file
    convert = b.T @ a  # target file from riderlive file
    scale = 1.0 / UNITS[bonemap.unit]
    renamed = {
        v_r: bonemap.joints[bone] for bone, v_r in load_bonemap("riderlive").joints.items() if bone in bonemap.joints
    }
    if bonemap.seat:
        renamed["rider"] = bonemap.seat
    axis = {"X": 0, "Y": 1, "Z": 2}
    i, j, k = (axis[c] for c in reversed(order))  # M = R_order[0] R_order[1] R_order[2] = R_k R_j R_i
    from riderlive.fit.bonemap import euler

    lines, columns = ["HIERARCHY"], []
    children: dict[int, list[int]] = {}
    for n, joint in enumerate(take.joints):
        children.setdefault(joint.parent, []).append(n)
    rotation_channels = " ".join(f"{c}rotation" for c in order)

    def emit(n: int, depth: int) -> None:
        joint = take.joints[n]
        pad = "\t" * depth
        name = renamed.get(joint.name, f"extra_{joint.name}")
        lines.append(f"{pad}{'ROOT' if joint.parent < 0 else 'JOINT'} {name}")
        lines.append(pad + "{")
        offset = convert @ joint.offset * scale
        lines.append(f"{pad}\tOFFSET {' '.join(repr(float(v)) for v in offset)}")
        lines.append(f"{pad}\tCHANNELS 6 Xposition Yposition Zposition {rotation_channels}")
        columns.append(take.positions[n] @ convert.T * scale)
        m = convert @ take.rotations[n] @ convert.T
        angles = euler(m, (i, j, k))  # about i, j, k
        by_axis = {i: angles[:, 0], j: angles[:, 1], k: angles[:, 2]}
        columns.append(np.column_stack([by_axis[axis[c]] for c in order]))
        for child in children.get(n, []):
            emit(child, depth + 1)
        if not children.get(n):
            lines.extend([f"{pad}\tEnd Site", pad + "\t{", f"{pad}\t\tOFFSET 0.0 0.1 0.0", pad + "\t}"])
        lines.append(pad + "}")

    emit(children[-1][0], 0)
    values = np.column_stack(columns)
    lines += ["MOTION", f"Frames: {len(values)}", f"Frame Time: {take.frame_time!r}"]
    lines += [" ".join(repr(float(v)) for v in row) for row in values]
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(("name", "order"), [("mixamo", "ZXY"), ("unity_humanoid", "ZXY"), ("riderlive_cm", "XYZ")])
def test_other_skeletons_axes_units_and_euler_orders_convert(
    baked: Path, tmp_path: Path, name: str, order: str
) -> None:
    take = read_bvh(str(full_precision_bvh(baked, tmp_path / "jump.rider.bvh")))
    want = rider_channels(take, load_bonemap("riderlive"))
    bonemap = load_bonemap(name)
    converted = tmp_path / f"{name}.bvh"
    converted.write_text(rewrite(take, bonemap, order))
    got = rider_channels(read_bvh(str(converted)), bonemap)
    assert set(got) == (set(bonemap.read) if bonemap.read is not None else set(want))
    for channel, values in got.items():
        np.testing.assert_array_equal(np.isnan(values), np.isnan(want[channel]), err_msg=channel)
        np.testing.assert_allclose(values, want[channel], rtol=0, atol=1e-9, err_msg=channel)


def test_every_shipped_map_loads() -> None:
    assert {"riderlive", "riderlive_cm", "mixamo", "unity_humanoid"} <= set(shipped_bonemaps())
    for name in shipped_bonemaps():
        assert load_bonemap(name).name == name


def test_a_different_skeleton_is_refused_by_name(baked: Path, tmp_path: Path) -> None:
    take = read_bvh(str(full_precision_bvh(baked, tmp_path / "jump.rider.bvh")))
    other = tmp_path / "other.bvh"
    other.write_text(rewrite(take, load_bonemap("mixamo"), "ZXY"))
    with pytest.raises(FitInputError, match="a different skeleton: no joint"):
        rider_channels(read_bvh(str(other)), load_bonemap("riderlive"))
    bad = tmp_path / "bad.bvh"
    bad.write_text(
        "HIERARCHY\nROOT a\n{\n\tOFFSET 0 0 0\n\tCHANNELS 3 Qrotation Xrotation Yrotation\n}\n"
        "MOTION\nFrames: 2\nFrame Time: 0.01\n0 0 0\n0 0 0\n"
    )
    with pytest.raises(FitInputError, match="unknown channel 'Qrotation'"):
        read_bvh(str(bad))
    with pytest.raises(FitInputError, match="not a BVH"):
        read_bvh(str(baked))


def test_a_rider_fitted_from_riderlives_bvh(baked: Path, tmp_path: Path) -> None:
    horse = tmp_path / "jump.csv"
    write_frames(str(horse), horse_table("jump"))
    record_scale(str(horse), METRES)
    bvh = full_precision_bvh(baked, tmp_path / "jump.rider.bvh")
    report = tmp_path / "fit.json"
    args = ["fit", str(horse), str(bvh), "-o", str(tmp_path / "r.toml"), "--report", str(report), "--quiet"]
    assert main(args) == 0
    import json

    data = json.loads(report.read_text())
    english = load_preset("english").flat()
    checked = 0
    for p in data["parameters"]:
        if p["identified"]:
            assert p["value"] == pytest.approx(english[p["name"]], rel=0.01, abs=1e-3), p["name"]
            checked += 1
    assert checked >= 30
    assert all(c["r"] is None or c["r"] > 0.9999 for c in data["takes"][0]["channels"])
