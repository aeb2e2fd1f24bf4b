"""Foxglove messages of riderlive: the topics, schemas and message bytes that MCAP files
(:mod:`riderlive.export.mcap`) and the live server (:mod:`riderlive.service.foxglove`) share.

| topic | schema (encoding) | what |
| --- | --- | --- |
| ``/rider/joints`` | ``riderlive.RiderJoints`` (JSON Schema, ``json``) | ``seq``, ``t``, ``timecode``, rider channels |
| ``/horse/joints`` | ``riderlive.HorseJoints`` (JSON Schema, ``json``) | ``seq``, ``t``, ``timecode``, horse channels |
| ``/tf`` | ``foxglove.FrameTransforms`` (the SDK's protobuf) | both skeletons as a frame tree |
| ``/status`` | ``riderlive.Status`` (JSON Schema, ``json``) | the service's status (live only) |

Channel names become field names with ``.`` replaced by ``_`` (``head.rx`` ->
``head_rx``: Foxglove's message paths cannot name a key with a dot). Lengths are metres,
angles degrees. Frames: ``world`` (Foxglove's: x forward, y left, z up) -> ``horse``
(the skeleton axes, x forward, y up, z right: +90 deg about x) -> ``horse/<bone>``;
the rider's ``rider`` frame is the horse's ``horse/saddle`` bone (identity), then
``rider/<bone>``; a take without a horse hangs ``rider`` on ``world``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import orjson

from riderlive.skeleton.rig import Rig

FloatArray = npt.NDArray[np.float64]

RIDER_TOPIC = "/rider/joints"
HORSE_TOPIC = "/horse/joints"
TF_TOPIC = "/tf"
STATUS_TOPIC = "/status"
WORLD = "world"
UP_Z = (math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5))
"""Skeleton axes (y up) in Foxglove's world (z up): +90 deg about x, x y z w."""


def field_name(channel: str) -> str:
    return channel.replace(".", "_")


def joints_schema(title: str, names: Sequence[str]) -> dict[str, Any]:
    """The JSON Schema of a joints message over channels ``names``."""
    properties: dict[str, Any] = {
        "seq": {"type": "integer", "description": "tick sequence number live, frame index in a file: gaps are drops"},
        "t": {"type": "number", "description": "seconds (engine time live; take time in a file)"},
        "timecode": {"type": "string", "description": "SMPTE label HH:MM:SS:FF (;FF drop-frame)"},
    }
    properties |= {field_name(n): {"type": "number", "description": n} for n in names}
    return {"title": title, "type": "object", "properties": properties}


STATUS_SCHEMA: dict[str, Any] = {
    "title": "riderlive.Status",
    "type": "object",
    "description": "The service's status: driver, mode, e-stop, devices (docs/protocol.md)",
    "additionalProperties": True,
}


@dataclass(frozen=True)
class Schemas:
    """Name, encoding and bytes of each topic's schema, and its message encoding."""

    topics: dict[str, tuple[str, str, bytes, str]]


def schemas(rider_names: Sequence[str], horse_names: Sequence[str]) -> Schemas:
    """Every topic's schema (``rider_names`` / ``horse_names``: the channels the joints carry)."""
    from foxglove.messages import FrameTransforms

    tf = FrameTransforms.get_schema()
    return Schemas(
        {
            RIDER_TOPIC: (
                "riderlive.RiderJoints",
                "jsonschema",
                _json(joints_schema("riderlive.RiderJoints", rider_names)),
                "json",
            ),
            HORSE_TOPIC: (
                "riderlive.HorseJoints",
                "jsonschema",
                _json(joints_schema("riderlive.HorseJoints", horse_names)),
                "json",
            ),
            TF_TOPIC: (tf.name, tf.encoding, bytes(tf.data), "protobuf"),
            STATUS_TOPIC: ("riderlive.Status", "jsonschema", _json(STATUS_SCHEMA), "json"),
        }
    )


def _json(obj: Any) -> bytes:
    return orjson.dumps(obj)


class JointsEncoder:
    """Joints messages over fixed channels (field names computed once: the live path's encoder)."""

    def __init__(self, names: tuple[str, ...]) -> None:
        self.keys = tuple(map(field_name, names))

    def encode(self, seq: int, t: float, timecode: str, values: Sequence[float] | FloatArray) -> bytes:
        floats = values.tolist() if isinstance(values, np.ndarray) else [float(v) for v in values]
        if len(floats) != len(self.keys):
            raise ValueError(f"{len(floats)} values for {len(self.keys)} channels")
        body: dict[str, Any] = {"seq": seq, "t": t, "timecode": timecode}
        body.update(zip(self.keys, floats, strict=True))
        return orjson.dumps(body)


@dataclass(frozen=True)
class SkeletonFrames:
    """One skeleton's frame ids: ``parent[b]`` and ``child[b]`` for each bone, its root's parent."""

    rig: Rig
    root: str
    root_parent: str

    @property
    def parents(self) -> list[str]:
        return [
            self.root if b.parent < 0 else f"{self.rig.name}/{self.rig.bones[b.parent].name}" for b in self.rig.bones
        ]

    @property
    def children(self) -> list[str]:
        return [f"{self.rig.name}/{b.name}" for b in self.rig.bones]


def skeleton_frames(horse: Rig | None, rider: Rig | None) -> list[SkeletonFrames]:
    out = []
    if horse is not None:
        out.append(SkeletonFrames(horse, horse.name, WORLD))
    if rider is not None:
        out.append(SkeletonFrames(rider, rider.name, f"{horse.name}/saddle" if horse is not None else WORLD))
    return out


def frame_transforms(
    time_ns: int,
    skeletons: Sequence[SkeletonFrames],
    poses: Sequence[tuple[FloatArray, FloatArray]],
) -> bytes:
    """``foxglove.FrameTransforms`` bytes at ``time_ns``: each skeleton's root (on ``world``:
    turned z up; on the saddle: identity) and every bone's local offset (B, 3, metres) and
    rotation (B, 4, x y z w) from ``poses``, in the order of ``skeletons``."""
    from foxglove.messages import FrameTransform, FrameTransforms, Quaternion, Timestamp, Vector3

    stamp = Timestamp(sec=time_ns // 1_000_000_000, nsec=time_ns % 1_000_000_000)
    transforms = []
    for frames, (offsets, rotations) in zip(skeletons, poses, strict=True):
        root = UP_Z if frames.root_parent == WORLD else (0.0, 0.0, 0.0, 1.0)
        x, y, z, w = root
        transforms.append(
            FrameTransform(
                timestamp=stamp,
                parent_frame_id=frames.root_parent,
                child_frame_id=frames.root,
                translation=Vector3(),
                rotation=Quaternion(x=x, y=y, z=z, w=w),
            )
        )
        for parent, child, p, q in zip(
            frames.parents, frames.children, offsets.tolist(), rotations.tolist(), strict=True
        ):
            transforms.append(
                FrameTransform(
                    timestamp=stamp,
                    parent_frame_id=parent,
                    child_frame_id=child,
                    translation=Vector3(x=p[0], y=p[1], z=p[2]),
                    rotation=Quaternion(x=q[0], y=q[1], z=q[2], w=q[3]),
                )
            )
    return bytes(FrameTransforms(transforms=transforms).encode())
