"""A take as an MCAP file (``riderlive export TAKE --format mcap``), Foxglove's log format.

The topics and schemas are the live server's (:mod:`riderlive.export.foxglove`): the
joints of each skeleton the take has (metres, degrees; with the frame's timecode) and the
skeletons as ``foxglove.FrameTransforms`` on ``/tf``, one message per topic per frame.
Log times are the take's start (sidecar ``started``, else the Unix epoch) plus each
frame's time. A ``riderlive`` metadata record names the take, its rate and its start
timecode. The writer is PyPI ``mcap``'s (chunked, zstd or lz4 when installed, else none).
"""

from __future__ import annotations

from datetime import datetime
from typing import IO

from riderlive.export import foxglove as fx
from riderlive.export.take import FloatArray, SkeletonTrack, TakePoses, timecode_fields


def start_ns(started: object) -> int:
    """The take's start as Unix nanoseconds (sidecar ``started``, ISO 8601), 0 when unknown."""
    if isinstance(started, str):
        try:
            return int(datetime.fromisoformat(started).timestamp() * 1e9)
        except ValueError:
            return 0
    return 0


def frame_labels(take: TakePoses) -> list[str]:
    """Each frame's timecode label ("" when the take has none)."""
    if take.timecode is None:
        return [""] * len(take.t)
    anchor = take.timecode.anchor(0.0)
    return [anchor.label_at(float(t)) for t in take.t]


def write_mcap(fh: IO[bytes], take: TakePoses, started_ns: int = 0) -> int:
    """Write ``take`` to a binary file; the number of messages written."""
    from mcap.writer import Writer

    horse_rig = take.horse.rig if take.horse is not None else None
    rider_rig = take.rider.rig if take.rider is not None else None
    tracks = [track for track in (take.horse, take.rider) if track is not None]
    frames = fx.skeleton_frames(horse_rig, rider_rig)
    rider_names, horse_names = take.rider_channels, take.horse_channels
    rider_values, horse_values = take.matrix(rider_names), take.matrix(horse_names)
    schemas = fx.schemas(rider_names, horse_names).topics
    writer = Writer(fh)
    writer.start(profile="", library="riderlive")
    channels: dict[str, int] = {}
    wanted = [fx.TF_TOPIC] + ([fx.RIDER_TOPIC] if rider_names else []) + ([fx.HORSE_TOPIC] if horse_names else [])
    for topic in wanted:
        name, encoding, data, message_encoding = schemas[topic]
        schema_id = writer.register_schema(name=name, encoding=encoding, data=data)
        channels[topic] = writer.register_channel(topic=topic, message_encoding=message_encoding, schema_id=schema_id)
    meta = {"take": take.name, "rate": f"{take.rate:g}", "frames": str(len(take.t)), **timecode_fields(take)}
    writer.add_metadata("riderlive", meta)
    labels = frame_labels(take)
    rider_joints, horse_joints = fx.JointsEncoder(rider_names), fx.JointsEncoder(horse_names)
    written = 0
    for k, t in enumerate(take.t.tolist()):
        time_ns = started_ns + round(t * 1e9)
        messages = [(fx.TF_TOPIC, fx.frame_transforms(time_ns, frames, _local(tracks, k)))]
        if rider_names:
            messages.append((fx.RIDER_TOPIC, rider_joints.encode(k, t, labels[k], rider_values[k])))
        if horse_names:
            messages.append((fx.HORSE_TOPIC, horse_joints.encode(k, t, labels[k], horse_values[k])))
        for topic, data in messages:
            writer.add_message(channels[topic], log_time=time_ns, data=data, publish_time=time_ns, sequence=k)
            written += 1
    writer.finish()  # type: ignore[no-untyped-call]
    return written


def _local(tracks: list[SkeletonTrack], k: int) -> list[tuple[FloatArray, FloatArray]]:
    """Frame ``k``'s local offsets and rotations of each track (bone-major arrays)."""
    return [(track.poses.local_offsets[:, k], track.poses.local_rotations[:, k]) for track in tracks]
