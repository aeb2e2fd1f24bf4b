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
import multiprocessing
import os
import socket
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.serving import burn  # noqa: E402

BAD_URL = "nats://127.0.0.1:99999"
COMMANDS = {
    "stage list": ["stage", "--nats", "{url}", "--stage", "A", "list"],
    "serve --nats": ["serve", "--nats", "{url}", "--rig", "r1", "--port", "0"],
}


def closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def mute_port() -> int:
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(64)
    held: list[socket.socket] = []

    def accept() -> None:
        while True:
            held.append(server.accept()[0])

    threading.Thread(target=accept, daemon=True).start()
    return int(server.getsockname()[1])


def wall_pair(command: list[str], url: str) -> tuple[float, float, int]:
    """(wall s of the command against url, wall s of its baseline, exit code), started together."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    start = time.perf_counter()
    procs = [
        subprocess.Popen(
            [sys.executable, "-m", "riderlive", *(a.format(url=u) for a in command)],
            env=env,
            cwd="/tmp",
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        for u in (url, BAD_URL)
    ]
    ends = [0.0, 0.0]

    def reap(i: int) -> None:  # each end timed by its own waiter: neither waits for the other
        procs[i].wait(300)
        ends[i] = time.perf_counter() - start

    waiters = [threading.Thread(target=reap, args=(i,)) for i in range(2)]
    for w in waiters:
        w.start()
    for w in waiters:
        w.join()
    return ends[0], ends[1], procs[0].returncode


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--no-burner", action="store_true")
    args = parser.parse_args()
    burners = []
    if not args.no_burner:
        ctx = multiprocessing.get_context("spawn")
        burners = [ctx.Process(target=burn, args=(time.perf_counter() + 600.0,)) for _ in range(2)]
        for b in burners:
            b.start()
    load = "2 burners" if burners else "no burner of its own"
    urls = {"closed": f"nats://127.0.0.1:{closed_port()}", "mute": f"nats://127.0.0.1:{mute_port()}"}
    print(
        f"host: {load}, load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores "
        f"({'loaded' if os.getloadavg()[0] >= 2 or burners else 'quiet'}); {args.runs} runs each; s from process start"
    )
    try:
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
                    wall, base, code = wall_pair(command, url)
                    walls.append(wall)
                    bases.append(base)
                    codes.add(code)
                extra = [w - b for w, b in zip(walls, bases, strict=True)]
                print(
                    f"{name:13s} {kind:6s} exit {sorted(codes)}  wall median {statistics.median(walls):5.2f} "
                    f"max {max(walls):5.2f}  baseline median {statistics.median(bases):5.2f}  "
                    f"connect (wall - baseline) median {statistics.median(extra):5.2f} max {max(extra):5.2f}  "
                    f"ratio {statistics.median(walls) / statistics.median(bases):4.2f}"
                )
    finally:
        for b in burners:
            b.terminate()
    return 0


if __name__ == "__main__":
    sys.exit(main())
