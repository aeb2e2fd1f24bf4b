"""Run by Blender's Python (bpy): Blender's own importers on exported files.

    python blender_import.py OUT.json TAKE.glb RIDER.bvh HORSE.bvh FRAME...

For the glTF file, once per bone-orientation option of ``bpy.ops.import_scene.gltf``:
every object (name, type, collections), whether it is some pose bone's custom shape, and
per armature its bone names and each bone's world head at the given take frames (0-based,
at the take's times). For the BVH files (``bpy.ops.import_anim.bvh`` with the scene's frame
rate taken from the file): the same per armature, the scene's fps and fps_base. What the
importers print (their warnings) goes to stdout, which the test reads.
"""

import json
import sys

import bpy

HEURISTICS = ("BLENDER", "TEMPERANCE", "FORTUNE")


def heads(obj, frame, subframe=0.0):
    bpy.context.scene.frame_set(frame, subframe=subframe)
    bpy.context.view_layer.update()
    return {b.name: list(obj.matrix_world @ b.head) for b in obj.pose.bones}


def scene_objects():
    shapes = {b.custom_shape.name for o in armatures() for b in o.pose.bones if b.custom_shape}
    return [
        {"name": o.name, "type": o.type, "collections": [c.name for c in o.users_collection], "shape": o.name in shapes}
        for o in bpy.data.objects
    ]


def armatures():
    return [o for o in bpy.data.objects if o.type == "ARMATURE"]


def main():
    out_path, glb, rider_bvh, horse_bvh = sys.argv[1:5]
    frames = [int(f) for f in sys.argv[5:]]
    result = {"gltf": {}, "bvh": {}}
    for heuristic in HEURISTICS:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        bpy.ops.import_scene.gltf(filepath=glb, bone_heuristic=heuristic)
        fps = bpy.context.scene.render.fps / bpy.context.scene.render.fps_base
        entry = {"objects": scene_objects(), "armatures": {}}
        for obj in armatures():
            bones = [b.name for b in obj.data.bones]
            poses = {}
            for k in frames:  # the take's frame k is at k / 120 s; the importer keys time t at frame t * fps
                when = k / 120.0 * fps
                poses[k] = heads(obj, int(when) + 0, when - int(when))
            entry["armatures"][obj.name] = {"bones": bones, "heads": poses}
        result["gltf"][heuristic] = entry
    bpy.ops.wm.read_factory_settings(use_empty=True)
    print("RIDERLIVE-BVH-START", flush=True)
    for path in (rider_bvh, horse_bvh):
        bpy.ops.import_anim.bvh(filepath=path, update_scene_fps=True)
    print("RIDERLIVE-BVH-END", flush=True)
    result["bvh"] = {
        "fps": bpy.context.scene.render.fps,
        "fps_base": bpy.context.scene.render.fps_base,
        "objects": scene_objects(),
        "armatures": {
            obj.name: {"bones": [b.name for b in obj.data.bones], "heads": {k: heads(obj, k + 1) for k in frames}}
            for obj in armatures()
        },
    }
    with open(out_path, "w") as fh:
        json.dump(result, fh)


main()
