"""What one ``riderlive serve`` start costs a test run, with and without the warm spare
(``tick.spare``; docs/performance.md, "The suite's wall time", branch ``livefast``).

Alternating rounds of each mode: start the real server (no device, the test suite's
settings: 200 Hz, no real-time priority), wait until it ticks, serve ``--serve-s`` seconds
and with a spare until it is warm (at its nice 10; the round's start without one serves as
long), stop it with SIGINT. Printed per
mode: the wall time to the first ticks, the CPU of the whole start-serve-stop (user + sys of
the server and every process it reaped: tick, spare; ``RUSAGE_CHILDREN``), the spare's
state at the stop, and the ratio of the medians.

    python bench/bench_serve_start.py [--rounds 4] [--serve-s 10] [--burners 0]
"""

from __future__ import annotations

import argparse
import resource
import signal
import statistics
import tempfile
import time
from pathlib import Path

import httpx

from bench.serving import busy_cores, start_server

CONFIG = """[tick]
rate = 200.0
realtime_priority = false
spare = {spare}
"""


def children_cpu() -> float:
    """User + sys seconds of the reaped children so far."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def one_start(spare: bool, serve_s: float) -> tuple[float, float, float, str]:
    """(s to the first ticks, s served, CPU s of start + serve + stop, the spare's state at
    the stop). Served ``serve_s`` and, with a spare, until it is warm (its whole warm-up)."""
    with tempfile.TemporaryDirectory() as folder:
        config = Path(folder) / "service.toml"
        config.write_text(CONFIG.format(spare=str(spare).lower()))
        cpu0, t0 = children_cpu(), time.perf_counter()
        proc, port = start_server(config, min_ticks=10.0, timeout=300.0)
        ticking = time.perf_counter() - t0

        def state() -> str:
            answer = httpx.get(f"http://127.0.0.1:{port}/api/devices", timeout=10).json()
            return str(answer["supervision"]["spare"]["state"])

        end, give_up = time.perf_counter() + serve_s, time.perf_counter() + 600.0
        while time.perf_counter() < end or (spare and state() != "warm" and time.perf_counter() < give_up):
            time.sleep(0.5)  # a bench's serving window, not a test's wait
        served, last = time.perf_counter() - t0 - ticking, state()
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=60)
        return ticking, served, children_cpu() - cpu0, last


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=4, help="starts of each mode, alternating")
    parser.add_argument("--serve-s", type=float, default=10.0, help="seconds served after the first ticks")
    parser.add_argument("--burners", type=int, default=0, help="busy processes at normal priority (2: both cores)")
    args = parser.parse_args()
    results: dict[bool, list[tuple[float, float, float, str]]] = {True: [], False: []}
    with busy_cores(args.burners) as load:
        for _ in range(args.rounds):
            serve_s = args.serve_s
            for spare in (True, False):  # without: served as long as the round's start with one
                results[spare].append(one_start(spare, serve_s))
                ticking, serve_s, cpu, state = results[spare][-1]
                print(
                    f"spare={str(spare).lower():5} ticking after {ticking:5.1f} s, served {serve_s:5.1f} s, "
                    f"CPU {cpu:5.2f} s, spare {state}",
                    flush=True,
                )
    print(f"{load}, {args.rounds} starts each, at least {args.serve_s:g} s served (with a spare: until warm):")
    medians = {}
    for spare, rows in results.items():
        medians[spare] = statistics.median(r[2] for r in rows)
        wall = statistics.median(r[0] for r in rows)
        print(f"  tick.spare = {str(spare).lower():5}: median {wall:5.1f} s to ticking, {medians[spare]:5.2f} s CPU")
    print(f"  CPU without / with the spare: {medians[False] / medians[True]:.2f}")


if __name__ == "__main__":
    main()
