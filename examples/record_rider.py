"""Record rider frames from a running ``riderlive serve`` into a frame file.

    python examples/record_rider.py rider.csv --seconds 10 --channels head.rz,lower_back.rz

``--url`` is the service's websocket base URL, ``ws://HOST:PORT`` (default
``ws://127.0.0.1:8000``, what ``riderlive serve`` listens on). A service that cannot be
reached is a one-line error (exit 2) within ``--timeout`` (5 s) of starting the script: the
time Python takes to start and import counts (the service is probed before the heavy imports,
with what is left of the budget, at least 0.5 s). The file has ``t`` (engine time, s)
and one column per channel; ``plot`` reads it.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import time

from riderlive.client import RiderSubscriber, ServiceUnreachable, probe, time_left


async def record(args: argparse.Namespace) -> None:
    channels = args.channels.split(",") if args.channels else None
    await probe(args.url, "/ws/rider", args.token, time_left(args.timeout))
    import numpy as np  # after the probe: seconds on a busy host

    from riderlive.framefile import FrameTable, write_frames

    sub = RiderSubscriber(args.url, channels=channels, rate=args.rate, token=args.token)
    times: list[float] = []
    rows: list[list[float]] = []
    names: list[str] = []
    stop_at = time.perf_counter() + args.seconds
    async for frame in sub.frames():
        if not names:
            names = list(frame.values)
        times.append(frame.t)
        rows.append([frame.values[n] for n in names])
        if time.perf_counter() >= stop_at:
            sub.close()
            break
    table = FrameTable(tuple(names), np.array(rows).reshape(len(rows), len(names)), np.array(times))
    write_frames(args.output, table)
    print(f"wrote {len(rows)} frames of {len(names)} channels to {args.output}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("output", help=".csv or .jsonl")
    parser.add_argument("--url", default="ws://127.0.0.1:8000", help="ws://HOST:PORT of riderlive serve")
    parser.add_argument("--timeout", type=float, default=5.0, help="seconds from start to reach the service")
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--channels", help="comma-separated rider channels (default all)")
    parser.add_argument("--rate", type=float, help="Hz (default: every tick)")
    parser.add_argument("--token")
    try:
        asyncio.run(record(parser.parse_args()))
    except ServiceUnreachable as exc:
        print(f"record_rider.py: {exc}", file=sys.stderr)
        sys.exit(2)
    except Exception as exc:
        from riderlive.framefile import FrameFileError  # imported late: see record()

        if not isinstance(exc, FrameFileError):
            raise
        print(f"record_rider.py: {exc}", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main()
