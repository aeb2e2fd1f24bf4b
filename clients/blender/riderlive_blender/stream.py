"""Live: a thread reads ``/ws/rider`` (binary frames with ``pose``), Blender applies the newest frame.

The reader thread keeps only the newest frame (it drains the socket, so a busy Blender
never sees a backlog); :meth:`LiveRider.apply_latest` runs on Blender's main thread
(from a ``bpy.app.timers`` callback at the viewport's pace) and poses the armatures.
"""

from __future__ import annotations

import json
import struct
import threading

from . import armature
from .wsclient import WebSocket

HEADER = struct.Struct("<4sHBBQddHHI")
EXTENSION = struct.Struct("<HHI")
FLAG_HORSE, FLAG_BONES, FLAG_POSE = 1, 2, 4


def decode(data: bytes) -> dict:
    """A binary frame (docs/protocol.md): seq, t, values, horse, and the pose floats of each skeleton."""
    magic, size, _, flags, seq, t, _, n_rider, n_horse, _ = HEADER.unpack_from(data)
    if magic != b"RLF1":
        raise ValueError("not a riderlive frame")
    offset, extension = size, HEADER.size
    values = struct.unpack_from(f"<{n_rider}d", data, offset)
    offset += 8 * n_rider
    horse = struct.unpack_from(f"<{n_horse}d", data, offset) if flags & FLAG_HORSE else ()
    offset += 8 * len(horse)
    if flags & FLAG_BONES:
        n_bones = EXTENSION.unpack_from(data, extension)[0]
        extension += EXTENSION.size
        offset += 8 * n_bones
    pose = {}
    if flags & FLAG_POSE:
        counts = EXTENSION.unpack_from(data, extension)[:2]
        for name, count in zip(("rider", "horse"), counts, strict=False):
            if count:
                pose[name] = struct.unpack_from(f"<{count}d", data, offset)
                offset += 8 * count
    return {"seq": seq, "t": t, "values": values, "horse": horse, "pose": pose}


class LiveRider:
    """Connects, builds the rider and horse armatures from the hello, and drives them."""

    def __init__(self, url: str, rate: float = 60.0, with_values: bool = False) -> None:
        """``with_values``: also receive every rider and horse channel (to inspect; the armatures need only poses)."""
        self.ws = WebSocket(url)
        hello = json.loads(self.ws.recv())
        self.skeletons = hello["skeletons"]
        request = {"type": "subscribe", "pose": True, "encoding": "binary", "rate": rate, "channels": []}
        if with_values:
            request["channels"] = [c["name"] for c in hello["channels"]]
            request["horse_channels"] = [c["name"] for c in hello["horse_channels"]]
        self.ws.send(json.dumps(request))
        self.names = {s: [b["name"] for b in self.skeletons[s]["bones"]] for s in ("rider", "horse")}
        self.parents = {s: [b["parent"] for b in self.skeletons[s]["bones"]] for s in ("rider", "horse")}
        self.objects = {s: armature.build(f"riderlive_{s}", self.skeletons[s]["bones"]) for s in ("rider", "horse")}
        self.latest: dict | None = None
        self.applied: dict | None = None
        self.error: str | None = None
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        try:
            while not self._stop.is_set():
                message = self.ws.recv()
                if isinstance(message, bytes):
                    frame = decode(message)
                    if frame["pose"]:
                        with self._lock:
                            self.latest = frame
        except (OSError, ValueError) as exc:
            if not self._stop.is_set():
                self.error = str(exc)

    def apply_latest(self) -> dict | None:
        """Pose the armatures from the newest frame (main thread); returns it, or None if nothing new."""
        with self._lock:
            frame, self.latest = self.latest, None
        if frame is None:
            return None
        horse = frame["pose"].get("horse")
        if horse is not None:
            armature.apply_pose(self.objects["horse"], self.names["horse"], horse)
            rot, pos = armature.world_pose(self.parents["horse"], horse)
            saddle = self.names["horse"].index("saddle")
            armature.place(self.objects["rider"], rot[saddle], pos[saddle])
        if "rider" in frame["pose"]:
            armature.apply_pose(self.objects["rider"], self.names["rider"], frame["pose"]["rider"])
        self.applied = frame
        return frame

    def close(self) -> None:
        self._stop.set()
        self.ws.close()
        self._thread.join(2.0)
