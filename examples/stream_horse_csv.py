"""Stream a horse take (CSV or JSONL frame file) into a running ``riderlive serve``.

    python examples/stream_horse_csv.py take.csv --url ws://127.0.0.1:8000 --loop

``--url`` is the service's websocket base URL, ``ws://HOST:PORT`` (default
``ws://127.0.0.1:8000``, what ``riderlive serve`` listens on). A service that cannot be
reached is a one-line error (exit 2) within ``--timeout`` (5 s) of starting the script: the time
Python takes to start and import counts (the service is probed before the take is read, with
what is left of the budget, at least 0.5 s). Frames go out at the take's own timing
(its ``t`` column, or --rate without one), with the length unit recorded beside the
take (``NAME.json``, as ``riderlive horse`` writes it) or ``--length-scale``.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import time

from riderlive.client import HorseProducer, ServiceUnreachable, probe, time_left


async def stream(args: argparse.Namespace) -> None:
    await probe(args.url, "/ws/rider", args.token, time_left(args.timeout))  # fail fast, before the heavy imports
    from riderlive.framefile import read_frames
    from riderlive.frameunits import recorded_scale

    table = read_frames(args.take)
    times = table.times(args.rate)
    rows = [dict(zip(table.names, row, strict=True)) for row in table.values.tolist()]
    scale = args.length_scale if args.length_scale is not None else recorded_scale(args.take)
    producer = HorseProducer(
        args.url,
        name=args.name,
        priority=args.priority,
        length_scale=scale,
        token=args.token,
        open_timeout=max(args.timeout, 5.0),
    )
    async with producer as horse:
        offset = 0.0
        while True:
            start = time.perf_counter() - float(times[0])
            for t, values in zip(times.tolist(), rows, strict=True):
                await asyncio.sleep(max(0.0, start + t - time.perf_counter()))
                await horse.send(offset + t, {k: v for k, v in values.items() if k != "t"})
            if not args.loop:
                break
            offset += float(times[-1] - times[0]) + (float(times[1] - times[0]) if len(times) > 1 else 0.0)
        print(f"sent {len(rows)} frames; driving: {horse.driving}; errors: {len(horse.errors)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("take", help="horse frames: .csv or .jsonl with horse channel columns")
    parser.add_argument("--url", default="ws://127.0.0.1:8000", help="ws://HOST:PORT of riderlive serve")
    parser.add_argument("--timeout", type=float, default=5.0, help="seconds from start to reach the service")
    parser.add_argument("--name", default="csv")
    parser.add_argument("--priority", type=int, default=0)
    parser.add_argument("--token", help="needed when the service requires one")
    parser.add_argument("--rate", type=float, default=120.0, help="Hz, for a file without a t column")
    parser.add_argument("--loop", action="store_true", help="start over at the end")
    parser.add_argument(
        "--length-scale", type=float, help="thesis rig units per the take's length unit (default: NAME.json, else 25)"
    )
    try:
        asyncio.run(stream(parser.parse_args()))
    except ServiceUnreachable as exc:
        print(f"stream_horse_csv.py: {exc}", file=sys.stderr)
        sys.exit(2)
    except Exception as exc:
        from riderlive.framefile import FrameFileError  # imported late: see stream()

        if not isinstance(exc, FrameFileError):
            raise
        print(f"stream_horse_csv.py: {exc}", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main()
