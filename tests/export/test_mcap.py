"""``riderlive export TAKE --format mcap``, read back with the official ``mcap`` reader and
``mcap-protobuf-support``'s decoder (``foxglove.FrameTransforms`` from the file's own schema)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from riderlive import timecode as tc
from riderlive.channels import HORSE_NAMES, RIDER_NAMES
from riderlive.cli import main
from riderlive.skeleton import HORSE_RIG, rider_rig
from riderlive.timecode import Rate
from tests.export.conftest import write_take

START = "10:00:00;00"


def _stamped_take(directory: Path, name: str, seconds: float = 0.5) -> Path:
    path = write_take(directory, name, seconds=seconds)
    meta = json.loads(path.with_suffix(".json").read_text())
    meta |= {"timecode": START, "timecode_rate": "29.97df", "timecode_source": "producer"}
    path.with_suffix(".json").write_text(json.dumps(meta))
    return path


def _export(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str]:
    code = main(["export", *argv, "--format", "mcap"])
    return code, capsys.readouterr().err


def _read(path: Path) -> tuple[dict[str, list[tuple[int, Any]]], dict[str, dict[str, str]], Any]:
    by_topic: dict[str, list[tuple[int, Any]]] = {}
    with path.open("rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        for schema, channel, message in reader.iter_messages():
            if channel.message_encoding == "json":
                decoded: Any = json.loads(message.data)
            else:
                decoded = DecoderFactory().decoder_for(channel.message_encoding, schema)(message.data)  # type: ignore[misc]
            by_topic.setdefault(channel.topic, []).append((message.log_time, decoded))
    return by_topic, metadata, summary


def test_a_take_round_trips_through_the_official_reader(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    take = _stamped_take(tmp_path, "canter")
    code, err = _export(capsys, str(take), "-o", str(tmp_path / "canter.mcap"))
    assert code == 0, err
    topics, metadata, summary = _read(tmp_path / "canter.mcap")
    rows = np.loadtxt(take, delimiter=",", skiprows=1)
    n = len(rows)
    assert {t: len(m) for t, m in topics.items()} == {"/tf": n, "/rider/joints": n, "/horse/joints": n}
    schemas = {s.name: s.encoding for s in summary.schemas.values()}
    assert schemas == {
        "foxglove.FrameTransforms": "protobuf",
        "riderlive.RiderJoints": "jsonschema",
        "riderlive.HorseJoints": "jsonschema",
    }
    assert metadata["riderlive"]["timecode"] == START and metadata["riderlive"]["timecode_rate"] == "29.97df"
    # joints: the take's own values (metres, degrees), the frame's timecode and time
    k = n - 1
    rider = topics["/rider/joints"][k][1]
    header = (take.read_text().splitlines()[0]).split(",")
    for name in ("lower_back.rz", "cog.ty", RIDER_NAMES[-1]):
        assert rider[name.replace(".", "_")] == pytest.approx(rows[k, header.index(name)], abs=1e-9)
    horse = topics["/horse/joints"][k][1]
    assert horse[HORSE_NAMES[0].replace(".", "_")] == pytest.approx(rows[k, header.index(HORSE_NAMES[0])], abs=1e-9)
    assert rider["t"] == pytest.approx(k / 120) and rider["seq"] == k
    expected = tc.format_frames(
        tc.parse(START, Rate.FPS_29_97_DF) + math.floor(k / 120 * 30000 / 1001 + 1e-6), Rate.FPS_29_97_DF
    )
    assert rider["timecode"] == expected
    assert topics["/rider/joints"][0][1]["timecode"] == START
    # log times: the sidecar's start plus the frame's time, strictly increasing
    times = [t for t, _ in topics["/tf"]]
    assert np.all(np.diff(times) > 0) and times[-1] - times[0] == round(k / 120 * 1e9)
    # frame tree: world -> horse (z up) -> bones; horse/saddle -> rider -> bones
    transforms = topics["/tf"][0][1].transforms
    parents = {t.child_frame_id: t.parent_frame_id for t in transforms}
    assert parents["horse"] == "world" and parents["rider"] == "horse/saddle"
    rig = rider_rig()
    assert len(transforms) == 2 + len(HORSE_RIG.bones) + len(rig.bones)
    root = next(t for t in transforms if t.child_frame_id == "horse")
    assert (root.rotation.x, root.rotation.w) == pytest.approx((math.sqrt(0.5), math.sqrt(0.5)))
    for bone in rig.bones[1:]:
        child = next(t for t in transforms if t.child_frame_id == f"rider/{bone.name}")
        assert child.parent_frame_id == f"rider/{rig.bones[bone.parent].name}"
        q = child.rotation
        assert q.x**2 + q.y**2 + q.z**2 + q.w**2 == pytest.approx(1.0)


def test_a_take_without_timecode_still_exports(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    take = write_take(tmp_path, "plain", seconds=0.1)
    code, err = _export(capsys, str(take), "-o", str(tmp_path / "plain.mcap"))
    assert code == 0, err
    topics, metadata, _ = _read(tmp_path / "plain.mcap")
    assert "timecode" not in metadata["riderlive"]
    assert topics["/rider/joints"][0][1]["timecode"] == ""


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("t," + ",".join(HORSE_NAMES) + "\n", "no frames"),
        ("t," + ",".join(HORSE_NAMES) + "\n0.0,1.0,zz\n", ""),
        ("", ""),
    ],
)
def test_an_empty_or_damaged_take_is_refused_and_nothing_is_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], content: str, message: str
) -> None:
    (tmp_path / "bad.csv").write_text(content)
    before = set(tmp_path.rglob("*"))
    code, err = _export(capsys, str(tmp_path / "bad.csv"), "-o", str(tmp_path / "bad.mcap"))
    assert code == 2 and err.startswith("riderlive export: ") and message in err
    assert set(tmp_path.rglob("*")) == before


def test_a_broken_sidecar_timecode_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    take = _stamped_take(tmp_path, "broken", seconds=0.1)
    meta = json.loads(take.with_suffix(".json").read_text()) | {"timecode": "10:00:00:00"}
    take.with_suffix(".json").write_text(json.dumps(meta))
    code, err = _export(capsys, str(take), "-o", str(tmp_path / "broken.mcap"))
    assert code == 2 and "timecode" in err
    assert not (tmp_path / "broken.mcap").exists()


def test_gltf_and_bvh_carry_the_timecode(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import pygltflib

    take = _stamped_take(tmp_path, "stamped", seconds=0.1)
    assert main(["export", str(take), "--format", "gltf", "-o", str(tmp_path / "s.glb")]) == 0
    extras = pygltflib.GLTF2().load(str(tmp_path / "s.glb")).asset.extras["riderlive"]
    assert extras["timecode"] == START and extras["timecode_rate"] == "29.97df"
    assert main(["export", str(take), "--format", "bvh", "-o", str(tmp_path / "s")]) == 0
    side = json.loads((tmp_path / "s.timecode.json").read_text())
    assert side["timecode"] == START and sorted(side["files"]) == ["s.horse.bvh", "s.rider.bvh"]
    assert (tmp_path / "s.rider.bvh").read_text().startswith("HIERARCHY\n")  # the BVH itself is untouched
