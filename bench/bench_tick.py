"""Tick lateness: the tick in its own process vs the same loop in a thread of a busy process.

    PYTHONPATH=. python bench/bench_tick.py --rate 500 --seconds 60
    PYTHONPATH=. python bench/bench_tick.py --rate 500 --seconds 30 --tail

Both runs use the real tick (TickLink: rules, procedural horse, shared-memory rings) at
the same rate, with the other core kept busy by a busy-loop process and this process's
main thread running busy Python code (standing in for the web process). Lateness and
the tick's compute time (woken to record written) are read per tick from the output
ring. Baseline: ``isolation = "thread"``; with ``--tail``, the tick in its own process
with the tail and braid physics on, against the same tick without it.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from bench.serving import busy_cores
from riderlive.realtime.core import Timing
from riderlive.realtime.link import TickLink
from riderlive.realtime.record import RecordLayout
from riderlive.realtime.setup import TickSetup
from riderlive.realtime.tail import physics_channels
from riderlive.rules import RuleParams
from riderlive.rules.animator import AnimatorLayer


def busy_python(link: TickLink, seconds: float) -> list[np.ndarray]:
    """Busy Python work in this process (like a web process), draining the ring as it goes."""
    records: list[np.ndarray] = []
    payload = {"values": list(range(60)), "name": "frame"}
    stop_at = time.perf_counter() + seconds
    while time.perf_counter() < stop_at:
        for _ in range(200):
            json.loads(json.dumps(payload))
        records.extend(link.read_outputs())
        link.drain_notify()
    records.extend(link.read_outputs())
    return records


def run(isolation: str, rate: float, seconds: float, realtime: bool, tail: bool = False) -> dict[str, float]:
    setup = TickSetup(
        rate=rate,
        start=time.perf_counter(),
        timing=Timing(),
        params=RuleParams(),
        animator=AnimatorLayer(),
        length_scale=25.0,
        realtime_priority=realtime,
        isolation=isolation,
        tail=tail,
        layout=RecordLayout(physics_channels() if tail else ()),
    )
    link = TickLink(setup)
    try:
        while link.counters.snapshot()["ticks"] < rate:  # spawned, imported, one second of ticks
            time.sleep(0.05)
        link.read_outputs()
        records = busy_python(link, seconds)
        status = link.status()
    finally:
        link.stop(3.0)
        link.close()
    data = np.array(records)
    late = data[:, RecordLayout.lateness.start] * 1e3
    cost = (data[:, RecordLayout.done.start] - data[:, RecordLayout.engine_t.start]) * 1e3 - late
    seq = data[:, RecordLayout.seq.start]
    expected = int(seq[-1] - seq[0]) + 1
    return {
        "ticks": float(len(data)),
        "skipped": float(expected - len(data)),
        "p50_ms": float(np.percentile(late, 50)),
        "p99_ms": float(np.percentile(late, 99)),
        "p999_ms": float(np.percentile(late, 99.9)),
        "max_ms": float(late.max()),
        "cost_p50_ms": float(np.percentile(cost, 50)),
        "cost_p99_ms": float(np.percentile(cost, 99)),
        "cost_max_ms": float(cost.max()),
        "realtime": 1.0 if status.get("realtime") == "fifo" else 0.0,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rate", type=float, default=500.0)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--baseline-seconds", type=float, help="default: --seconds")
    parser.add_argument("--no-burner", action="store_true")
    parser.add_argument("--no-realtime", action="store_true")
    parser.add_argument("--tail", action="store_true", help="tail + braid physics on vs off (both in their process)")
    args = parser.parse_args()
    total = args.seconds + (args.baseline_seconds or args.seconds) + 10
    with busy_cores(0 if args.no_burner else 1, total):
        design = run("process", args.rate, args.seconds, not args.no_realtime, tail=args.tail)
        baseline_isolation = "process" if args.tail else "thread"
        baseline = run(baseline_isolation, args.rate, args.baseline_seconds or args.seconds, not args.no_realtime)
    print(f"tick at {args.rate:g} Hz, other core busy: {not args.no_burner}, SCHED_FIFO: {bool(design['realtime'])}")
    labels = ("tail on", "tail off (baseline)") if args.tail else ("own process (design)", "thread (baseline)")
    print(f"{'':22}{'ticks':>8}{'skipped':>9}  lateness ms: {'p50':>7}{'p99':>7}{'p99.9':>7}{'max':>7}", end="")
    print(f"  compute ms: {'p50':>7}{'p99':>7}{'max':>7}")
    for label, r in zip(labels, (design, baseline), strict=True):
        print(
            f"{label:22}{r['ticks']:8.0f}{r['skipped']:9.0f}{'':15}{r['p50_ms']:7.3f}{r['p99_ms']:7.3f}"
            f"{r['p999_ms']:7.3f}{r['max_ms']:7.3f}{'':14}{r['cost_p50_ms']:7.3f}{r['cost_p99_ms']:7.3f}"
            f"{r['cost_max_ms']:7.3f}"
        )
    if args.tail:
        ratio = design["cost_p50_ms"] / max(baseline["cost_p50_ms"], 1e-6)
        print(f"compute p50 ratio tail on/off: {ratio:.1f}x")
    else:
        print(f"p99 ratio baseline/design: {baseline['p99_ms'] / max(design['p99_ms'], 1e-6):.1f}x")
    ok = design["p99_ms"] <= 0.5 and design["max_ms"] <= 3.0 and design["skipped"] == 0
    print(f"target (p99 <= 0.5 ms, max <= 3 ms, no skipped tick): {'met' if ok else 'NOT met'}")


if __name__ == "__main__":
    main()
