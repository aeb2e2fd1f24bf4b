"""Import a take exported by ``riderlive export TAKE --format gltf`` as keyframed armatures.

Reads the .glb itself (JSON chunk + binary chunk, numpy), builds one armature per
skin with :func:`armature.build` (the skin's root node, ``rider`` or ``horse``, becomes
the armature object: its animation keys the object), and keys every pose bone with
``fcurve.keyframe_points.foreach_set`` (fast for long takes).
"""

from __future__ import annotations

import json
import struct

import bpy
import numpy as np

from . import armature

_GLTF = armature._FROM_GLTF
_COMPONENTS = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def read_glb(path: str) -> tuple[dict, bytes]:
    with open(path, "rb") as fh:
        data = fh.read()
    magic, version, _ = struct.unpack_from("<4sII", data)
    if magic != b"glTF" or version != 2:
        raise ValueError(f"{path}: not a binary glTF 2.0 file")
    size, _ = struct.unpack_from("<I4s", data, 12)
    gltf = json.loads(data[20 : 20 + size])
    bin_size, _ = struct.unpack_from("<I4s", data, 20 + size)
    return gltf, data[28 + size : 28 + size + bin_size]


def accessor(gltf: dict, blob: bytes, index: int) -> np.ndarray:
    acc = gltf["accessors"][index]
    view = gltf["bufferViews"][acc["bufferView"]]
    width = _COMPONENTS[acc["type"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    return np.frombuffer(blob, dtype="<f4", count=acc["count"] * width, offset=start).reshape(acc["count"], width)


def _fcurves(obj: bpy.types.Object, name: str):
    """A new action on ``obj`` and a function making its fcurves (slotted actions from Blender 4.4, else legacy)."""
    action = bpy.data.actions.new(name)
    obj.animation_data_create()
    obj.animation_data.action = action
    if hasattr(action, "slots"):
        slot = action.slots.new(id_type="OBJECT", name=obj.name)
        obj.animation_data.action_slot = slot
        bag = action.layers.new("take").strips.new(type="KEYFRAME").channelbag(slot, ensure=True)
        return lambda path, index: bag.fcurves.new(path, index=index)
    return lambda path, index: action.fcurves.new(path, index=index)


def _key(new_fcurve, path: str, frames: np.ndarray, values: np.ndarray) -> None:
    for k in range(values.shape[-1]):
        curve = new_fcurve(path, k)
        curve.keyframe_points.add(len(frames))
        curve.keyframe_points.foreach_set("co", np.column_stack((frames, values[:, k])).ravel().astype(np.float32))
        curve.update()


def import_take(path: str) -> list[bpy.types.Object]:
    """Armatures of the take's skeletons, keyed at the scene's frame rate (set to the take's)."""
    gltf, blob = read_glb(path)
    nodes = gltf["nodes"]
    parent_of = {c: i for i, n in enumerate(nodes) for c in n.get("children", [])}
    animation = gltf["animations"][0]
    scene = bpy.context.scene
    rate = float(gltf["asset"].get("extras", {}).get("riderlive", {}).get("rate", 60.0))
    scene.render.fps = max(1, round(rate))
    tracks: dict[tuple[int, str], np.ndarray] = {}
    times = None
    for channel in animation["channels"]:
        sampler = animation["samplers"][channel["sampler"]]
        times = accessor(gltf, blob, sampler["input"])[:, 0]
        tracks[(channel["target"]["node"], channel["target"]["path"])] = accessor(gltf, blob, sampler["output"])
    frames = 1.0 + np.asarray(times, dtype=np.float64) * scene.render.fps
    objects = []
    for skin in gltf["skins"]:
        root, joints = skin["joints"][0], skin["joints"][1:]
        index = {node: i for i, node in enumerate(joints)}
        bones = [
            {
                "name": nodes[j]["name"],
                "parent": index.get(parent_of.get(j, -1), -1),
                "offset": armature.vectors(np.array(nodes[j].get("translation", [0.0, 0.0, 0.0])), _GLTF).tolist(),
            }
            for j in joints
        ]
        obj = armature.build(skin["name"], bones)
        names = [b["name"] for b in bones]
        n = len(frames)
        pose = np.zeros((n, len(bones), armature.FLOATS_PER_BONE))
        pose[..., 6] = 1.0
        for i, j in enumerate(joints):
            pose[:, i, :3] = bones[i]["offset"]
            if (j, "translation") in tracks:
                pose[:, i, :3] = armature.vectors(tracks[(j, "translation")], _GLTF)
            if (j, "rotation") in tracks:
                pose[:, i, 3:] = armature.quaternions(tracks[(j, "rotation")], _GLTF)
        rotation, location = armature.basis(obj, names, pose.reshape(n, -1))
        new_fcurve = _fcurves(obj, f"{skin['name']}_take")
        root_pos = armature.vectors(armature.vectors(tracks[(root, "translation")], _GLTF))
        root_rot = armature.quaternions(armature.quaternions(tracks[(root, "rotation")], _GLTF))
        obj.rotation_mode = "QUATERNION"
        _key(new_fcurve, "location", frames, root_pos)
        _key(new_fcurve, "rotation_quaternion", frames, root_rot[:, [3, 0, 1, 2]])
        for i, name in enumerate(names):
            _key(new_fcurve, f'pose.bones["{name}"].rotation_quaternion', frames, rotation[:, i][:, [3, 0, 1, 2]])
            _key(new_fcurve, f'pose.bones["{name}"].location', frames, location[:, i])
        objects.append(obj)
    scene.frame_start, scene.frame_end = 1, round(frames[-1])
    return objects
