"""Takes in JetStream: record a rig's frames on the broker, list, replay into any rig, export.

A take is a JetStream stream ``RLTAKE_<stage>_<take>`` that captures one rig's
``...<rig>.frame`` subject for ``--seconds``, with retention limits (``--max-age``,
``--max-mb``: the broker discards the oldest frames past them, and the stream
disappears ``max-age`` after it was made). When the time is up the stream stops
capturing (its subject is moved to ``riderlive.takes.<stage>.<take>``), so the same rig
can be recorded again. One take per rig at a time: JetStream refuses two streams on one
subject (a clear error). The rig's local takes directory (``POST /api/record/start``)
is unaffected: both can run at once.

- ``replay`` publishes the take's horse channels into any rig as a NATS producer
  (``...<rig>.horse.replay-<take>``, hello priority ``--priority``), at the original
  timing: the target's arbiter, ranges and safety apply as to any producer.
- ``export`` writes a local take file (the same CSV + sidecar as the service's
  recorder), which ``riderlive bake``, ``export`` and ``PUT /api/source`` use.

JetStream is NATS's; another engine would need its own persistence here.
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import orjson

from riderlive.bus.subjects import Kind, Stage, check_name
from riderlive.bus.transport import Transport, TransportError
from riderlive.channels import HORSE_NAMES, RIDER_NAMES
from riderlive.service.rider_frames import BINARY_MAGIC, decode_binary_frame

PREFIX = "RLTAKE"


def stream_name(stage: Stage, take: str) -> str:
    return f"{PREFIX}_{stage.name}_{check_name(take, 'take')}"


def _js(transport: Transport) -> Any:
    client = getattr(transport, "client", None)
    if client is None:
        raise TransportError("takes in JetStream need the NATS transport")
    return client.jetstream()


@dataclass(frozen=True)
class TakeInfo:
    name: str
    rig: str
    frames: int
    bytes: int
    recording: bool
    first_seq: int
    last_seq: int


async def record(
    transport: Transport, stage: Stage, rig: str, take: str, *, seconds: float, max_age: float, max_bytes: int
) -> TakeInfo:
    """Capture ``rig``'s frames for ``seconds`` into a new take stream; its info at the end."""
    from nats.js.api import DiscardPolicy, StorageType, StreamConfig
    from nats.js.errors import BadRequestError

    js = _js(transport)
    name = stream_name(stage, take)
    meta = {"stage": stage.name, "rig": check_name(rig, "rig"), "take": take, "started": time.time()}
    config = StreamConfig(
        name=name,
        subjects=[stage.rig(rig).subject(Kind.FRAME)],
        description=orjson.dumps(meta).decode(),
        max_age=max_age,
        max_bytes=max_bytes,
        discard=DiscardPolicy.OLD,
        storage=StorageType.FILE,
    )
    try:
        await js.add_stream(config)
    except BadRequestError as exc:
        raise TransportError(f"cannot record take {take!r}: {exc.description}") from None
    try:
        await asyncio.sleep(seconds)
    finally:
        await js.update_stream(dataclasses.replace(config, subjects=[f"riderlive.takes.{stage.name}.{take}"]))
    return await info(transport, stage, take)


def _info_of(raw: Any) -> TakeInfo:
    meta = orjson.loads(raw.config.description or "{}")
    subjects = raw.config.subjects or []
    return TakeInfo(
        name=str(meta.get("take", raw.config.name)),
        rig=str(meta.get("rig", "?")),
        frames=int(raw.state.messages),
        bytes=int(raw.state.bytes),
        recording=any(s.endswith(".frame") for s in subjects),
        first_seq=int(raw.state.first_seq),
        last_seq=int(raw.state.last_seq),
    )


async def info(transport: Transport, stage: Stage, take: str) -> TakeInfo:
    from nats.js.errors import NotFoundError

    try:
        return _info_of(await _js(transport).stream_info(stream_name(stage, take)))
    except NotFoundError:
        raise TransportError(f"no take {take!r} on stage {stage.name!r}") from None


async def list_takes(transport: Transport, stage: Stage) -> list[TakeInfo]:
    prefix = f"{PREFIX}_{stage.name}_"
    streams = await _js(transport).streams_info()
    return sorted((_info_of(s) for s in streams if s.config.name.startswith(prefix)), key=lambda t: t.name)


async def frames(transport: Transport, stage: Stage, take: str) -> list[dict[str, Any]]:
    """Every frame of a take, oldest first, decoded (``t``, ``values``, ``horse``)."""
    js = _js(transport)
    take_info = await info(transport, stage, take)
    name = stream_name(stage, take)
    out = []
    for seq in range(take_info.first_seq, take_info.last_seq + 1):
        msg = await js.get_msg(name, seq)
        data = bytes(msg.data or b"")
        out.append(decode_binary_frame(data) if data[:4] == BINARY_MAGIC else orjson.loads(data))
    return [f for f in out if "horse" in f]


async def replay(
    transport: Transport,
    stage: Stage,
    take: str,
    rig: str,
    *,
    priority: int = 0,
    token: str | None = None,
    speed: float = 1.0,
) -> int:
    """Publish a take's horse frames into ``rig`` at their timing; frames sent."""
    recorded = await frames(transport, stage, take)
    subject = stage.rig(rig).horse(f"replay-{take}")
    hello: dict[str, Any] = {"type": "hello", "priority": priority}
    if token is not None:
        hello["token"] = token
    await transport.publish(subject, orjson.dumps(hello))
    start = time.perf_counter()
    t0 = recorded[0]["t"] if recorded else 0.0
    for frame in recorded:
        due = start + (frame["t"] - t0) / speed
        delay = due - time.perf_counter()
        if delay > 0:
            await asyncio.sleep(delay)
        body = {"t": time.time(), "v": frame["horse"]}
        await transport.publish(subject, orjson.dumps(body))
    await transport.publish(subject, orjson.dumps({"type": "bye"}))
    await transport.flush()
    return len(recorded)


async def export(transport: Transport, stage: Stage, take: str, out: Path) -> int:
    """Write a take as a local take file (CSV + sidecar); rows written."""
    from riderlive.takes.recorder import TakeRecorder

    recorded = await frames(transport, stage, take)
    recorder = TakeRecorder(out, meta={"source": f"jetstream {stream_name(stage, take)}"})
    try:
        for frame in recorded:
            horse, rider = frame["horse"], frame["values"][: len(RIDER_NAMES)]
            if len(horse) != len(HORSE_NAMES) or len(rider) != len(RIDER_NAMES):
                raise TransportError(f"take {take!r} frames carry {len(horse)} horse channels, not {len(HORSE_NAMES)}")
            recorder.add(float(frame["t"]), horse, rider)
    finally:
        recorder.close()
    return len(recorded)


async def export_mcap(transport: Transport, stage: Stage, take: str, out: Path) -> int:
    """Write a take as MCAP (the schemas of ``riderlive export --format mcap``, through a local
    take file in a temporary directory); messages written. Nothing is written for a take
    without frames (TransportError) or one the skeletons cannot pose."""
    import tempfile

    from riderlive.export.mcap import start_ns, write_mcap
    from riderlive.export.take import ExportError, load_take, sidecar_of
    from riderlive.framefile import _atomic_binary

    with tempfile.TemporaryDirectory() as tmp:
        local = Path(tmp) / f"{take}.csv"
        if await export(transport, stage, take, local) == 0:
            raise TransportError(f"take {take!r} has no frames: no MCAP written")
        try:
            poses = load_take(local)
        except ExportError as exc:
            raise TransportError(f"take {take!r}: {exc}") from None
        with _atomic_binary(str(out)) as fh:
            return write_mcap(fh, poses, start_ns(sidecar_of(local).get("started")))


def add_take_arguments(sub: Any) -> None:
    rec = sub.add_parser("record", help="record a rig's frames into a JetStream take")
    rec.add_argument("--rig", required=True)
    rec.add_argument("--take", required=True)
    rec.add_argument("--seconds", type=float, default=10.0)
    rec.add_argument("--max-age", type=float, default=7 * 86400.0, help="retention: seconds (default 7 days)")
    rec.add_argument("--max-mb", type=float, default=256.0, help="retention: megabytes (default 256)")
    rec.add_argument("--mcap", type=Path, metavar="FILE", help="also write the take as MCAP (docs/foxglove.md)")
    sub.add_parser("takes", help="list the stage's JetStream takes")
    rep = sub.add_parser("replay", help="replay a JetStream take into a rig (as a NATS producer)")
    rep.add_argument("--take", required=True)
    rep.add_argument("--rig", required=True)
    rep.add_argument("--priority", type=int, default=0)
    rep.add_argument("--token", help="the target service's security.token, when it needs one")
    exp = sub.add_parser("export", help="write a JetStream take as a local take file (for riderlive bake)")
    exp.add_argument("--take", required=True)
    exp.add_argument("--out", required=True, type=Path)


async def run_take_action(transport: Transport, stage: Stage, args: argparse.Namespace) -> int:
    if args.action == "record":
        max_bytes = int(args.max_mb * 1024 * 1024)
        got = await record(
            transport, stage, args.rig, args.take, seconds=args.seconds, max_age=args.max_age, max_bytes=max_bytes
        )
        print(f"take {got.name!r}: {got.frames} frames of rig {got.rig!r}, {got.bytes} bytes")
        if args.mcap is not None:
            written = await export_mcap(transport, stage, args.take, args.mcap)
            print(f"wrote {written} MCAP messages to {args.mcap}")
        return 0
    if args.action == "takes":
        for t in await list_takes(transport, stage):
            state = "recording" if t.recording else "complete"
            print(f"{t.name}  rig={t.rig}  frames={t.frames}  bytes={t.bytes}  {state}")
        return 0
    if args.action == "replay":
        sent = await replay(transport, stage, args.take, args.rig, priority=args.priority, token=args.token)
        print(f"replayed {sent} frames of {args.take!r} into rig {args.rig!r}")
        return 0
    rows = await export(transport, stage, args.take, args.out)
    print(f"wrote {rows} rows to {args.out}")
    return 0
