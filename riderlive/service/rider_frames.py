"""Wire formats of the websockets, the way out: one tick record as a ``/ws/rider`` frame (docs/protocol.md).

Pure. :func:`encode_frame` turns one output record into the bytes a
:class:`~riderlive.service.codecs.Subscription` asks for, JSON text or the little-endian
binary layout :data:`BINARY_HEADER` (float64 values in the service's length unit and
degrees, engine seconds); :func:`decode_binary_frame` is its inverse, for clients and tests.
"""

from __future__ import annotations

import math
import struct
from typing import Any

import numpy as np
import orjson

from riderlive.realtime.record import RecordLayout
from riderlive.realtime.saddle_input import GAITS, LOCKS
from riderlive.service.codecs import Subscription

BINARY_MAGIC = b"RLF1"
BINARY_HEADER = struct.Struct("<4sHBBQddHHI")
"""magic, header size, driver, flags, seq, engine_t, source_t, n_rider, n_horse, reserved."""
BONES_HEADER = struct.Struct("<HHI")
"""Appended to the header when flag bit 1 is set: n_bones (floats), reserved, reserved."""
POSE_HEADER = struct.Struct("<HHI")
"""Appended (after the bones block, if any) when flag bit 2 is set: rider pose floats, horse pose floats, reserved."""
SADDLE_HEADER = struct.Struct("<HHBBH")
"""Appended (after the bones and pose blocks, if any) when flag bit 3 is set: saddle floats (6),
estimate floats (3: stride_hz, phase, age), lock code, gait code (255: none), reserved."""
FLAG_HORSE = 1
FLAG_BONES = 2
FLAG_POSE = 4
FLAG_SADDLE = 8
FLAG_TIMECODE = 16
"""The header's last (reserved) u32 is the frame's timecode: frames since 00:00:00:00 at the hello's rate."""
NO_CODE = 255
DRIVERS = ("procedural", "input", "neutral")


def _code(value: float) -> int:
    return NO_CODE if math.isnan(value) else int(value)


def saddle_estimate(row: np.ndarray) -> dict[str, Any] | None:
    """The estimate block of a record (``record.ESTIMATE_FIELDS``) as published (None: no saddle input drives)."""
    lock, gait, stride_hz, phase, age = (float(x) for x in row)
    if math.isnan(lock):
        return None
    return {
        "lock": LOCKS[int(lock)],
        "gait": None if math.isnan(gait) else GAITS[int(gait)],
        "stride_hz": stride_hz,
        "phase": phase,
        "age": None if math.isnan(age) else age,
    }


def encode_frame(
    sub: Subscription,
    record: np.ndarray,
    bones: np.ndarray | None = None,
    pose: dict[str, np.ndarray] | None = None,
    timecode: tuple[int, str] | None = None,
) -> str | bytes:
    """One output-ring record as a frame for ``sub``: JSON text or the binary layout (docs/protocol.md).

    ``timecode``: the record's (frames, label), added when ``sub.timecode``.

    ``bones``: the rider's bone quaternions for this record, added when ``sub.bones``.
    ``pose``: skeleton -> its pose floats (7 per bone) for this record, added for ``sub.pose``.
    """
    seq = RecordLayout.seq.count(record)
    engine_t = RecordLayout.engine_t.at(record)
    source_t = RecordLayout.source_t.at(record)
    driver = RecordLayout.driver.count(record)
    horse = record[RecordLayout.horse.slice]
    rider = record[RecordLayout.rider.start :]
    rider_values = rider[list(sub.rider)] if len(sub.rider) != len(rider) else rider
    horse_values = horse[list(sub.horse)] if sub.horse else None
    bone_values = bones if sub.bones else None
    poses = [np.asarray(pose[name], dtype="<f8") if pose else np.zeros(0) for name in sub.pose]
    saddle = record[RecordLayout.saddle.slice]
    estimate = record[RecordLayout.estimate.slice]
    if sub.encoding == "binary":
        flags = (FLAG_HORSE if horse_values is not None else 0) | (FLAG_BONES if bone_values is not None else 0)
        flags |= (FLAG_POSE if sub.pose else 0) | (FLAG_SADDLE if sub.saddle else 0)
        stamped = sub.timecode and timecode is not None
        flags |= FLAG_TIMECODE if stamped else 0
        size = BINARY_HEADER.size + (BONES_HEADER.size if bone_values is not None else 0)
        size += (POSE_HEADER.size if sub.pose else 0) + (SADDLE_HEADER.size if sub.saddle else 0)
        header = BINARY_HEADER.pack(
            BINARY_MAGIC,
            size,
            driver,
            flags,
            seq,
            engine_t,
            source_t,
            len(rider_values),
            0 if horse_values is None else len(horse_values),
            timecode[0] if stamped and timecode is not None else 0,
        )
        if bone_values is not None:
            header += BONES_HEADER.pack(len(bone_values), 0, 0)
        if sub.pose:
            counts = {name: len(p) for name, p in zip(sub.pose, poses, strict=True)}
            header += POSE_HEADER.pack(counts.get("rider", 0), counts.get("horse", 0), 0)
        if sub.saddle:
            header += SADDLE_HEADER.pack(len(saddle), 3, _code(estimate[0]), _code(estimate[1]), 0)
        body = rider_values.astype("<f8").tobytes()
        if horse_values is not None:
            body += horse_values.astype("<f8").tobytes()
        if bone_values is not None:
            body += np.asarray(bone_values, dtype="<f8").tobytes()
        body += b"".join(p.tobytes() for p in poses)
        if sub.saddle:
            body += saddle.astype("<f8").tobytes() + estimate[2:].astype("<f8").tobytes()
        return header + body
    message: dict[str, Any] = {
        "type": "frame",
        "seq": seq,
        "t": engine_t,
        "source_t": source_t,
        "driver": DRIVERS[driver],
        "values": rider_values.tolist(),
    }
    if horse_values is not None:
        message["horse"] = horse_values.tolist()
    if bone_values is not None:
        message["bones"] = np.asarray(bone_values).tolist()
    if sub.pose:
        message["pose"] = {name: p.tolist() for name, p in zip(sub.pose, poses, strict=True)}
    if sub.saddle:
        message["saddle"] = saddle.tolist()
        message["estimate"] = saddle_estimate(estimate)
    if sub.timecode and timecode is not None:
        message["tc"] = timecode[1]
    return orjson.dumps(message).decode()


def decode_binary_frame(data: bytes) -> dict[str, Any]:
    """The inverse of the binary layout (for clients and tests)."""
    magic, size, driver, flags, seq, engine_t, source_t, n_rider, n_horse, tc_frames = BINARY_HEADER.unpack_from(data)
    if magic != BINARY_MAGIC:
        raise ValueError("not a riderlive binary frame")
    rider = np.frombuffer(data, dtype="<f8", count=n_rider, offset=size)
    out: dict[str, Any] = {
        "type": "frame",
        "seq": seq,
        "t": engine_t,
        "source_t": source_t,
        "driver": DRIVERS[driver] if driver < len(DRIVERS) else driver,
        "values": rider.tolist(),
    }
    if flags & FLAG_TIMECODE:
        out["tc_frames"] = tc_frames
    if flags & FLAG_HORSE:
        out["horse"] = np.frombuffer(data, dtype="<f8", count=n_horse, offset=size + 8 * n_rider).tolist()
    offset = size + 8 * (n_rider + (n_horse if flags & FLAG_HORSE else 0))
    extension = BINARY_HEADER.size
    if flags & FLAG_BONES:
        (n_bones, _, _) = BONES_HEADER.unpack_from(data, extension)
        extension += BONES_HEADER.size
        out["bones"] = np.frombuffer(data, dtype="<f8", count=n_bones, offset=offset).tolist()
        offset += 8 * n_bones
    if flags & FLAG_POSE:
        n_rider_pose, n_horse_pose, _ = POSE_HEADER.unpack_from(data, extension)
        out["pose"] = {}
        extension += POSE_HEADER.size
        for name, count in (("rider", n_rider_pose), ("horse", n_horse_pose)):
            if count:
                out["pose"][name] = np.frombuffer(data, dtype="<f8", count=count, offset=offset).tolist()
                offset += 8 * count
    if flags & FLAG_SADDLE:
        n_saddle, n_estimate, lock, gait, _ = SADDLE_HEADER.unpack_from(data, extension)
        out["saddle"] = np.frombuffer(data, dtype="<f8", count=n_saddle, offset=offset).tolist()
        stride_hz, phase, age = np.frombuffer(data, dtype="<f8", count=n_estimate, offset=offset + 8 * n_saddle)[:3]
        row = np.array(
            [np.nan if lock == NO_CODE else lock, np.nan if gait == NO_CODE else gait, stride_hz, phase, age]
        )
        out["estimate"] = saddle_estimate(row)
    return out
