"""riderlive for Blender: drive armatures live from ``/ws/rider``; import a take as keyframes.

Install: zip this folder (``riderlive_blender``) and add it in Edit > Preferences >
Add-ons (or Get Extensions > Install from Disk on Blender 4.2+). Then, in the 3D
view's sidebar (N), tab "riderlive": set the URL (``ws://127.0.0.1:8000/ws/rider``)
and press Connect: two armatures appear, ``riderlive_rider`` and ``riderlive_horse``,
and follow the service at the viewport's pace. "Import take" reads a ``.glb`` written
by ``riderlive export TAKE --format gltf`` and keys both armatures at the take's rate.
Only Blender's own Python is needed (the websocket client is in ``wsclient.py``).

Live mode runs on ``bpy.app.timers``, which only an interactive Blender fires: in background
Blender (``blender -b``, a render farm, a script) Connect shows nothing. There, step it
yourself with :func:`drive` (``--frames``-style: apply N new frames, optionally keying each)::

    blender -b scene.blend --python-expr "import riderlive_blender as r; r.drive('ws://HOST:8000/ws/rider', frames=600, key=True)"
"""

from __future__ import annotations

import bpy
from bpy.props import StringProperty

from . import stream, take

bl_info = {
    "name": "riderlive",
    "author": "riderlive",
    "version": (0, 1, 0),
    "blender": (4, 2, 0),
    "location": "View3D > Sidebar > riderlive",
    "description": "Drive armatures live from a riderlive service; import riderlive takes",
    "category": "Animation",
}

_live: dict[str, stream.LiveRider] = {}
"""The connected session, if any (``"session"``)."""


def _tick() -> float | None:
    """Timer: pose from the newest frame; stop when disconnected."""
    session = _live.get("session")
    if session is None:
        return None
    session.apply_latest()
    return 1.0 / 60.0


def drive(url: str, frames: int, key: bool = False, timeout: float = 10.0) -> int:
    """Background Blender's live mode: connect, apply ``frames`` new frames as they come (what the
    timer does interactively), key both armatures' pose bones at scene frames 1, 2, ... with
    ``key``; returns how many were applied (fewer when none comes for ``timeout`` seconds)."""
    import time

    session = stream.LiveRider(url)
    applied, waited_since = 0, time.monotonic()
    try:
        while applied < frames:
            if session.apply_latest() is None:
                if time.monotonic() - waited_since > timeout:
                    break
                time.sleep(0.002)
                continue
            waited_since = time.monotonic()
            applied += 1
            if key:
                for obj in session.objects.values():
                    for bone in obj.pose.bones:
                        bone.keyframe_insert("rotation_quaternion", frame=applied)
                        bone.keyframe_insert("location", frame=applied)
    finally:
        session.close()
    return applied


class RIDERLIVE_OT_connect(bpy.types.Operator):
    bl_idname = "riderlive.connect"
    bl_label = "Connect"

    def execute(self, context):
        if "session" in _live:
            _live.pop("session").close()
        try:
            _live["session"] = stream.LiveRider(context.scene.riderlive_url)
        except (OSError, ValueError) as exc:
            self.report({"ERROR"}, f"riderlive: {exc}")
            return {"CANCELLED"}
        bpy.app.timers.register(_tick)
        return {"FINISHED"}


class RIDERLIVE_OT_disconnect(bpy.types.Operator):
    bl_idname = "riderlive.disconnect"
    bl_label = "Disconnect"

    def execute(self, context):
        if "session" in _live:
            _live.pop("session").close()
        return {"FINISHED"}


class RIDERLIVE_OT_import_take(bpy.types.Operator):
    bl_idname = "riderlive.import_take"
    bl_label = "Import take (.glb)"
    filepath: StringProperty(subtype="FILE_PATH")

    def execute(self, context):
        take.import_take(self.filepath)
        return {"FINISHED"}

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}


class RIDERLIVE_PT_panel(bpy.types.Panel):
    bl_label = "riderlive"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "riderlive"

    def draw(self, context):
        layout = self.layout
        layout.prop(context.scene, "riderlive_url")
        row = layout.row()
        row.operator("riderlive.connect")
        row.operator("riderlive.disconnect")
        session = _live.get("session")
        if session is not None and session.error:
            layout.label(text=f"error: {session.error}")
        layout.operator("riderlive.import_take")


_CLASSES = (RIDERLIVE_OT_connect, RIDERLIVE_OT_disconnect, RIDERLIVE_OT_import_take, RIDERLIVE_PT_panel)


def register() -> None:
    bpy.types.Scene.riderlive_url = StringProperty(name="URL", default="ws://127.0.0.1:8000/ws/rider")
    for cls in _CLASSES:
        bpy.utils.register_class(cls)


def unregister() -> None:
    for cls in reversed(_CLASSES):
        bpy.utils.unregister_class(cls)
    del bpy.types.Scene.riderlive_url
