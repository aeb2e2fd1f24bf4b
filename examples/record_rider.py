"""Record rider frames from a running ``riderlive serve`` into a frame file.

    python examples/record_rider.py rider.csv --seconds 10 --channels head.rz,lower_back.rz

The file has ``t`` (engine time, s) and one column per channel; ``plot`` reads it.
"""

from __future__ import annotations

import argparse
import asyncio
import time

import numpy as np

from riderlive.client import RiderSubscriber
from riderlive.framefile import FrameTable, write_frames


async def record(args: argparse.Namespace) -> None:
    channels = args.channels.split(",") if args.channels else None
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
    parser.add_argument("--url", default="ws://127.0.0.1:8000")
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--channels", help="comma-separated rider channels (default all)")
    parser.add_argument("--rate", type=float, help="Hz (default: every tick)")
    parser.add_argument("--token")
    asyncio.run(record(parser.parse_args()))


if __name__ == "__main__":
    main()
