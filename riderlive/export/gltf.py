"""A take as one binary glTF 2.0 file (``.glb``): both skeletons and one animation.

glTF's axes and units (right-handed, +Y up, the characters face +Z, metres). Each
skeleton is a static node ``NAME_armature`` (identity, not a joint: the armature object
an importer makes) holding a node tree under a root node named after the skeleton
(``horse``: the world origin; ``rider``: its seat point, animated with the horse's
``saddle`` so the rider rides the horse), one node per bone with its rest offset as
``translation`` (rest rotations are identity), and a skin listing the root and bone
nodes (inverse bind matrices of the rest pose), so engines and Blender import each
skeleton as its own armature (Blender: two armatures, each with one ``hips``). The animation ``take`` has,
per node, a ``rotation`` channel (local, relative to the rest) and, for the root node
and every bone that translates, a ``translation`` channel (the full local position),
sampled ``LINEAR`` at the take's frames. The asset's ``extras.riderlive`` names the
take, its rate, the skeleton version and the start timecode (``timecode``,
``timecode_rate``, ``timecode_source``: docs/timecode.md) when the take has one.
"""

from __future__ import annotations

import struct
from typing import IO, Any

import numpy as np
import numpy.typing as npt
import orjson

from riderlive import __version__
from riderlive.export import axes
from riderlive.export.take import SkeletonTrack, TakePoses, timecode_fields
from riderlive.skeleton import SKELETON_VERSION

FloatArray = npt.NDArray[np.float64]
FLOAT = 5126
"""glTF componentType for float32."""
ARMATURE_SUFFIX = "_armature"
"""Each skeleton's joints hang under a static node ``NAME_armature`` outside its skin: importers
(Blender's) make the nearest common ancestor of a skin's joints that is not a joint the armature,
so each skeleton becomes its own armature (without it, the scene root: one armature for both)."""


class _Builder:
    """Accumulates the binary buffer and the JSON's buffer views and accessors."""

    def __init__(self) -> None:
        self.blobs: list[bytes] = []
        self.size = 0
        self.views: list[dict[str, Any]] = []
        self.accessors: list[dict[str, Any]] = []

    def accessor(self, data: FloatArray, kind: str, bounds: bool = False) -> int:
        array = np.ascontiguousarray(data, dtype="<f4")
        blob = array.tobytes()
        self.views.append({"buffer": 0, "byteOffset": self.size, "byteLength": len(blob)})
        self.blobs.append(blob)
        self.size += len(blob)  # float32 data keeps every view 4-byte aligned
        accessor: dict[str, Any] = {
            "bufferView": len(self.views) - 1,
            "componentType": FLOAT,
            "count": int(array.shape[0]),
            "type": kind,
        }
        if bounds:
            flat = array.reshape(array.shape[0], -1)
            accessor["min"] = flat.min(axis=0).astype(float).tolist()
            accessor["max"] = flat.max(axis=0).astype(float).tolist()
        self.accessors.append(accessor)
        return len(self.accessors) - 1


def _skeleton(gltf: dict[str, Any], builder: _Builder, track: SkeletonTrack, time: int, anim: dict[str, Any]) -> int:
    """Add one skeleton's nodes, skin and animation channels; return its armature node."""
    rig = track.rig
    nodes = gltf["nodes"]
    armature = len(nodes)
    nodes.append({"name": f"{rig.name}{ARMATURE_SUFFIX}", "children": [armature + 1]})
    base = armature + 1
    rest_root = axes.positions(track.root_position[0])
    nodes.append({"name": rig.name, "translation": rest_root.tolist(), "children": []})
    rest_world = [np.zeros(3)] * len(rig.bones)
    for i, bone in enumerate(rig.bones):
        offset = axes.positions(np.asarray(bone.offset))
        rest_world[i] = offset if bone.parent < 0 else rest_world[bone.parent] + offset
        nodes.append({"name": bone.name, "translation": offset.tolist()})
        parent = base if bone.parent < 0 else base + 1 + bone.parent
        nodes[parent].setdefault("children", []).append(base + 1 + i)
    joints = list(range(base, base + 1 + len(rig.bones)))
    inverse_bind = np.tile(np.eye(4), (len(joints), 1, 1))
    for k, position in enumerate([np.zeros(3), *rest_world]):
        inverse_bind[k, :3, 3] = -(rest_root + position)
    matrices = builder.accessor(inverse_bind.transpose(0, 2, 1).reshape(len(joints), 16), "MAT4")
    gltf["skins"].append({"name": rig.name, "joints": joints, "skeleton": base, "inverseBindMatrices": matrices})

    def channel(node: int, path: str, values: FloatArray) -> None:
        anim["samplers"].append(
            {
                "input": time,
                "output": builder.accessor(values, "VEC4" if path == "rotation" else "VEC3"),
                "interpolation": "LINEAR",
            }
        )
        anim["channels"].append({"sampler": len(anim["samplers"]) - 1, "target": {"node": node, "path": path}})

    channel(base, "translation", axes.positions(track.root_position))
    channel(base, "rotation", axes.rotations(track.root_rotation))
    moving = {d.bone for d in rig.translations}
    rotations = axes.rotations(track.poses.local_rotations)
    offsets = axes.positions(track.poses.local_offsets)
    for i, bone in enumerate(rig.bones):
        if bone.name in moving:
            channel(base + 1 + i, "translation", offsets[i])
        channel(base + 1 + i, "rotation", rotations[i])
    return armature


def write_glb(fh: IO[bytes], take: TakePoses) -> None:
    """The take as a GLB (header, JSON chunk, BIN chunk) to a binary file."""
    builder = _Builder()
    gltf: dict[str, Any] = {
        "asset": {
            "version": "2.0",
            "generator": f"riderlive {__version__}",
            "extras": {
                "riderlive": {
                    "take": take.name,
                    "rate": take.rate,
                    "skeleton_version": SKELETON_VERSION,
                    **timecode_fields(take),
                }
            },
        },
        "scene": 0,
        "scenes": [{"name": take.name, "nodes": []}],
        "nodes": [],
        "skins": [],
    }
    time = builder.accessor(take.t, "SCALAR", bounds=True)
    anim: dict[str, Any] = {"name": "take", "channels": [], "samplers": []}
    for track in (take.horse, take.rider):
        if track is not None:
            gltf["scenes"][0]["nodes"].append(_skeleton(gltf, builder, track, time, anim))
    gltf["animations"] = [anim]
    gltf["buffers"] = [{"byteLength": builder.size}]
    gltf["bufferViews"] = builder.views
    gltf["accessors"] = builder.accessors
    text = orjson.dumps(gltf)
    text += b" " * (-len(text) % 4)
    pad = -builder.size % 4
    total = 12 + 8 + len(text) + 8 + builder.size + pad
    fh.write(struct.pack("<4sII", b"glTF", 2, total))
    fh.write(struct.pack("<I4s", len(text), b"JSON"))
    fh.write(text)
    fh.write(struct.pack("<I4s", builder.size + pad, b"BIN\x00"))
    for blob in builder.blobs:
        fh.write(blob)
    fh.write(b"\x00" * pad)
