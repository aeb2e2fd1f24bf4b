"""Run by Blender's Python (bpy): drive the add-on's armatures from a live service, then import a take.

    python blender_drive.py WS_URL SECONDS OUT.json [TAKE.glb FRAME...]

Writes what Blender evaluated: per applied frame, the streamed channel values and each
bone's world rotation (w x y z) and head position, plus the bones' rest rotations;
for the take, the rider's and horse's bone heads at the given frames.
"""

import json
import sys
import time

import bpy
import riderlive_blender
from riderlive_blender import stream, take


def bones_world(obj):
    out = {}
    for pose_bone in obj.pose.bones:
        matrix = obj.matrix_world @ pose_bone.matrix
        q = matrix.to_quaternion()
        out[pose_bone.name] = {"rotation": [q.w, q.x, q.y, q.z], "head": list(matrix.translation)}
    return out


def main():
    url, seconds, out_path = sys.argv[1], float(sys.argv[2]), sys.argv[3]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    riderlive_blender.register()
    live = stream.LiveRider(url, rate=50.0, with_values=True)
    rest = {
        s: {b.name: list(b.matrix_local.to_quaternion()) for b in live.objects[s].data.bones}
        for s in ("rider", "horse")
    }
    samples = []
    applied = []
    end = None
    while end is None or time.perf_counter() < end:
        frame = live.apply_latest()  # what the add-on's timer does at the viewport's pace
        if frame is None:
            time.sleep(0.002)
            continue
        if end is None:
            end = time.perf_counter() + seconds  # drive for SECONDS from the first frame
        applied.append({"seq": frame["seq"], "t": frame["t"]})
        if len(applied) % 3 != 1:
            continue  # Blender evaluates and the test compares every third frame applied
        bpy.context.view_layer.update()
        samples.append(
            {
                "seq": frame["seq"],
                "values": list(frame["values"]),
                "horse": list(frame["horse"]),
                "rider_bones": bones_world(live.objects["rider"]),
                "horse_bones": bones_world(live.objects["horse"]),
            }
        )
    live.close()
    result = {"rest": rest, "samples": samples, "applied": applied, "error": live.error}
    if len(sys.argv) > 4:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        objects = take.import_take(sys.argv[4])
        result["take"] = {}
        for frame in map(int, sys.argv[5:]):
            bpy.context.scene.frame_set(frame)
            bpy.context.view_layer.update()
            result["take"][frame] = {obj.name: bones_world(obj) for obj in objects}
        result["fps"] = bpy.context.scene.render.fps
    with open(out_path, "w") as fh:
        json.dump(result, fh)


main()
