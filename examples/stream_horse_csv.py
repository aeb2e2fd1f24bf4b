"""Stream a horse take (CSV or JSONL frame file) into a running ``riderlive serve``.

    python examples/stream_horse_csv.py take.csv --url ws://127.0.0.1:8000 --loop

Frames go out at the take's own timing (its ``t`` column, or --rate without one).
"""

from __future__ import annotations

import argparse
import asyncio
import time

from riderlive.client import HorseProducer
from riderlive.framefile import read_frames


async def stream(args: argparse.Namespace) -> None:
    table = read_frames(args.take)
    times = table.times(args.rate)
    rows = [dict(zip(table.names, row, strict=True)) for row in table.values.tolist()]
    async with HorseProducer(args.url, name=args.name, priority=args.priority, token=args.token) as horse:
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
    parser.add_argument("--url", default="ws://127.0.0.1:8000")
    parser.add_argument("--name", default="csv")
    parser.add_argument("--priority", type=int, default=0)
    parser.add_argument("--token", help="needed when the service requires one")
    parser.add_argument("--rate", type=float, default=120.0, help="Hz, for a file without a t column")
    parser.add_argument("--loop", action="store_true", help="start over at the end")
    asyncio.run(stream(parser.parse_args()))


if __name__ == "__main__":
    main()
