"""``riderlive stage``: see every rig of a stage, stop them all, beat the stage's heart, keep takes.

    riderlive stage --nats nats://stage-host:4222 --stage A list
    riderlive stage --nats ... --stage A estop                 # every rig latches its e-stop
    riderlive stage --nats ... --stage A heartbeat             # the stage heartbeat (10 Hz), until Ctrl-C
    riderlive stage --nats ... --stage A record --rig r1 --take t1 --seconds 30
    riderlive stage --nats ... --stage A takes
    riderlive stage --nats ... --stage A replay --take t1 --rig r2
    riderlive stage --nats ... --stage A export --take t1 --out takes/t1.csv   # then riderlive bake

Exit status: 0 done, 1 nobody answered (list, estop), 2 bad arguments or no broker.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import signal
import socket
import sys
import time
from typing import Any

import orjson

from riderlive.bus.subjects import Kind, Stage, check_name
from riderlive.bus.transport import Message, Transport, TransportError
from riderlive.timecode import Rate, TimecodeError, parse_rate

Timecode = tuple[Rate, float, str]
"""A heartbeat's timecode: rate, offset (s) and clock (local or utc), as ``[timecode]``."""
HEARTBEAT_PERIOD_S = 0.1
"""The heartbeat's period: 10 per ``nats.heartbeat_timeout`` (1 s) by default."""


def preflight(section: Any) -> str | None:
    """What stops ``serve --nats`` from joining (no broker, refused credentials, name taken), or None."""
    from riderlive.bus.nats import connect, credentials_of
    from riderlive.bus.rig import check_name_free

    async def check() -> None:
        transport = await connect(section.url, credentials_of(section), connect_timeout=section.connect_timeout)
        try:
            await check_name_free(transport, Stage(section.stage), section.rig)
        finally:
            await transport.close()

    try:
        asyncio.run(check())
    except TransportError as exc:
        return str(exc)
    return None


async def gather_replies(transport: Transport, subject: str, data: bytes, wait: float) -> list[dict[str, Any]]:
    """Publish a request and collect every reply that arrives within ``wait`` s."""
    inbox = transport.new_inbox()
    replies: list[dict[str, Any]] = []

    async def collect(msg: Message) -> None:
        with contextlib.suppress(orjson.JSONDecodeError):
            replies.append(orjson.loads(msg.data))

    sub = await transport.subscribe(inbox, collect)
    try:
        await transport.publish(subject, data, reply=inbox)
        await transport.flush()
        await asyncio.sleep(wait)
    finally:
        await sub.unsubscribe()
    return replies


async def discover(transport: Transport, stage: Stage, wait: float = 0.5) -> list[dict[str, Any]]:
    """Every rig's status, sorted by rig name."""
    replies = await gather_replies(transport, stage.subject(Kind.DISCOVER), b"{}", wait)
    return sorted(replies, key=lambda r: str(r.get("rig")))


async def stage_estop(transport: Transport, stage: Stage, by: str, wait: float = 0.5) -> list[dict[str, Any]]:
    """Send the stage e-stop; the acknowledgements (rig, latched_at) that arrive within ``wait``."""
    body = orjson.dumps({"by": by, "t": time.time()})
    return await gather_replies(transport, stage.subject(Kind.ESTOP), body, wait)


async def beat(
    transport: Transport, stage: Stage, period: float, stop: asyncio.Event, timecode: Timecode | None = None
) -> int:
    """Publish the stage heartbeat every ``period`` s until ``stop``; how many were sent.

    ``timecode`` (rate, offset s, clock): each beat carries ``tc`` (the host clock's label)
    and ``tc_rate``, the stage-wide timecode reference of every rig (docs/timecode.md)."""
    subject = stage.subject(Kind.HEARTBEAT)
    source = socket.gethostname()
    sent = 0
    next_at = time.perf_counter()
    while not stop.is_set():
        body: dict[str, Any] = {"seq": sent, "t": time.time(), "source": source}
        if timecode is not None:
            from riderlive.service.timecodes import host_label

            body |= {"tc": host_label(*timecode, wall=body["t"]), "tc_rate": timecode[0].value}
        await transport.publish(subject, orjson.dumps(body))
        sent += 1
        next_at += period
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), max(0.0, next_at - time.perf_counter()))
    return sent


def format_rigs(rigs: list[dict[str, Any]]) -> str:
    rows = [("rig", "host", "tick", "e-stop", "devices", "ticks/s", "frames/s", "horse/s", "heartbeat")]
    for r in rigs:
        rates = r.get("rates") or {}
        devices = ", ".join(f"{d['name']}={d['state']}" for d in r.get("devices", [])) or "-"
        hb = r.get("heartbeat") or {}
        age = hb.get("age")
        rows.append(
            (
                str(r.get("rig")),
                f"{r.get('host')}:{r.get('pid')}",
                "up" if r.get("tick_up") else "DOWN",
                "LATCHED" if r.get("estop") else "-",
                devices,
                f"{rates.get('ticks_hz', 0.0):.1f}",
                f"{rates.get('frames_out_hz', 0.0):.1f}",
                f"{rates.get('horse_in_hz', 0.0):.1f}",
                ("ok" if hb.get("ok") else "LOST") + ("" if age is None else f" {age:.2f}s"),
            )
        )
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip() for row in rows)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--nats", required=True, metavar="URL", help="nats://HOST:4222 (comma-separated: a cluster)")
    parser.add_argument("--stage", default="stage", help="stage name (default: stage)")
    parser.add_argument("--user", help="NATS user")
    parser.add_argument("--password", help="NATS password")
    parser.add_argument("--nats-token", help="NATS auth token")
    parser.add_argument("--creds", help="NATS .creds file")
    parser.add_argument("--tls-ca", help="CA file for tls:// servers")
    parser.add_argument("--wait", type=float, default=0.5, help="seconds to collect answers (list, estop)")
    sub = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    listing = sub.add_parser("list", help="every rig on the stage: state and rates")
    listing.add_argument("--json", action="store_true", help="print the status messages as JSON lines")
    stop = sub.add_parser("estop", help="the stage e-stop: every rig latches (reset each on its own)")
    stop.add_argument("--by", default=socket.gethostname(), help="who stops (logged by the rigs)")
    heart = sub.add_parser("heartbeat", help="publish the stage heartbeat until Ctrl-C")
    heart.add_argument("--period", type=float, default=HEARTBEAT_PERIOD_S, help="seconds between beats")
    heart.add_argument("--duration", type=float, default=0.0, help="stop after this many seconds (0: never)")
    heart.add_argument("--tc-rate", help="carry the stage timecode at this rate (25, 29.97df...; docs/timecode.md)")
    heart.add_argument("--tc-offset", type=float, default=0.0, help="seconds added to the host clock's time of day")
    heart.add_argument("--tc-clock", choices=("local", "utc"), default="local", help="time of day: local or utc")
    from riderlive.bus.takes import add_take_arguments

    add_take_arguments(sub)


async def _run(args: argparse.Namespace) -> int:
    from riderlive.bus.nats import Credentials, connect

    stage = Stage(check_name(args.stage, "stage"))
    credentials = Credentials(
        user=args.user, password=args.password, token=args.nats_token, creds=args.creds, tls_ca=args.tls_ca
    )
    transport = await connect(args.nats, credentials, f"riderlive stage {args.action}")
    try:
        if args.action == "list":
            rigs = await discover(transport, stage, args.wait)
            if args.json:
                for rig in rigs:
                    print(orjson.dumps(rig).decode())
            else:
                print(format_rigs(rigs) if rigs else f"no rig answers on stage {stage.name!r}")
            return 0 if rigs else 1
        if args.action == "estop":
            acks = await stage_estop(transport, stage, args.by, args.wait)
            names = sorted(str(a.get("rig")) for a in acks)
            print(f"stage {stage.name!r} e-stop sent; latched by {len(names)} rig(s): {', '.join(names) or 'none'}")
            return 0 if names else 1
        if args.action == "heartbeat":
            done = asyncio.Event()
            loop = asyncio.get_running_loop()
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.add_signal_handler(sig, done.set)
            if args.duration > 0:
                loop.call_later(args.duration, done.set)
            timecode = None if args.tc_rate is None else (parse_rate(args.tc_rate), args.tc_offset, args.tc_clock)
            print(f"heartbeat: stage {stage.name!r} every {args.period:g} s", flush=True)
            sent = await beat(transport, stage, args.period, done, timecode)
            print(f"heartbeat: {sent} sent", flush=True)
            return 0
        from riderlive.bus.takes import run_take_action

        return await run_take_action(transport, stage, args)
    finally:
        await transport.close()


def run(args: argparse.Namespace) -> int:
    try:
        return asyncio.run(_run(args))
    except (TransportError, ValueError, TimecodeError) as exc:
        print(f"riderlive stage: {exc}", file=sys.stderr)
        return 2
