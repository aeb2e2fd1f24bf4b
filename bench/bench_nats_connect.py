"""How fast a broker that is not there fails ``riderlive stage`` and ``serve --nats``.

    .venv/bin/python bench/bench_nats_connect.py [--runs 5] [--no-burner]

For a closed port and for a mute socket (accepts, never speaks NATS), ``--runs`` times
each: the wall time from process start to exit 2 of the real CLI, and the same command's
baseline started at the same moment with a URL nats-py rejects before any network (port
99999: the same imports and event loop). The difference is what the connect costs; the
ratio is wall / baseline. Two burner processes keep both cores busy unless
``--no-burner`` (say which with every figure: docs/performance.md).
"""

from __future__ import annotations

import argparse
import asyncio
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.serving import busy_cores  # noqa: E402
from tests.bus.dead_brokers import closed_port, mute_port, race_with_baseline  # noqa: E402

COMMANDS = {
    "stage list": ["stage", "--nats", "{url}", "--stage", "A", "list"],
    "serve --nats": ["serve", "--nats", "{url}", "--rig", "r1", "--port", "0"],
}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--no-burner", action="store_true")
    args = parser.parse_args()
    with busy_cores(0 if args.no_burner else 2, 600.0) as state, mute_port() as mute:
        urls = {"closed": f"nats://127.0.0.1:{closed_port()}", "mute": f"nats://127.0.0.1:{mute}"}
        print(f"host: {state}, load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; {args.runs} runs each")
        from riderlive.bus.nats import connect
        from riderlive.bus.transport import Unreachable

        for kind, url in urls.items():  # the connect alone, in this process: no start-up noise
            times = []
            for _ in range(args.runs):
                start = time.perf_counter()
                try:
                    asyncio.run(connect(url))
                except Unreachable:
                    times.append(time.perf_counter() - start)
            print(
                f"connect() in process {kind:6s} Unreachable {len(times)}/{args.runs}  "
                f"median {statistics.median(times):5.3f} max {max(times):5.3f} (connect_timeout 2 s)"
            )
        for name, command in COMMANDS.items():
            for kind, url in urls.items():
                walls, bases, codes = [], [], set()
                for _ in range(args.runs):
                    with tempfile.TemporaryDirectory() as cwd:
                        run, base = race_with_baseline(command, url, Path(cwd))
                    walls.append(run.wall_s)
                    bases.append(base.wall_s)
                    codes.add(run.code)
                extra = [w - b for w, b in zip(walls, bases, strict=True)]
                print(
                    f"{name:13s} {kind:6s} exit {sorted(codes)}  wall median {statistics.median(walls):5.2f} "
                    f"max {max(walls):5.2f}  baseline median {statistics.median(bases):5.2f}  "
                    f"connect (wall - baseline) median {statistics.median(extra):5.2f} max {max(extra):5.2f}  "
                    f"ratio {statistics.median(walls) / statistics.median(bases):4.2f}"
                )
    return 0


if __name__ == "__main__":
    sys.exit(main())
