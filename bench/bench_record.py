"""The tick's per-tick bookkeeping: the record packed by the layout and the typed counters,
against what the tick did before (a list literal; counters indexed by name), in the same run.

    PYTHONPATH=. python bench/bench_record.py            # the other core busy (the bench's burner)
    PYTHONPATH=. python bench/bench_record.py --no-burner

Each figure is the best of ``--repeats`` runs of ``--n`` calls, in microseconds of this thread's
CPU time per call (a loaded host's other processes do not count; caches and frequency still
do); the ratio is new / old.
"""

from __future__ import annotations

import argparse
import multiprocessing
import time
import timeit

from bench.serving import burn
from riderlive.channels import HORSE_NAMES, RIDER_NAMES
from riderlive.channels import RIDER_PART_NAMES as PART_NAMES
from riderlive.realtime.counters import COUNTERS, TickCounters
from riderlive.realtime.record import RecordLayout
from riderlive.realtime.shm import SharedCounters, SharedRing


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=20000)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--no-burner", action="store_true")
    args = parser.parse_args()
    burner = None
    if not args.no_burner:
        burner = multiprocessing.get_context("spawn").Process(target=burn, args=(time.perf_counter() + 600.0,))
        burner.start()
    try:
        rows = measure(args.n, args.repeats)
    finally:
        if burner is not None:
            burner.terminate()
            burner.join()
    print(f"per tick, best of {args.repeats} x {args.n}, other core busy: {not args.no_burner}")
    print(f"{'':34}{'new us':>9}{'old us':>9}{'new/old':>9}  (CPU us per call)")
    for label, new, old in rows:
        print(f"{label:34}{new:9.3f}{old:9.3f}{new / old:9.2f}")


def measure(n: int, repeats: int) -> list[tuple[str, float, float]]:
    layout = RecordLayout(tuple(f"tail_{i:02d}.rx" for i in range(24)), PART_NAMES)
    saddle, estimate = [0.1] * 6, (float("nan"),) * 5
    horse, rider = [0.2] * len(HORSE_NAMES), [0.3] * len(RIDER_NAMES)
    physics, parts = [0.4] * 24, [0.5] * len(PART_NAMES)
    ring = SharedRing(64, layout.width)
    shared = SharedCounters(COUNTERS)
    counter = TickCounters(shared.values)
    values, index = shared.values, shared.index
    bucket0 = index["lateness_bucket_0"]

    def pack_new() -> None:
        ring.write(
            layout.pack(
                seq=7,
                engine_t=1.0,
                source_t=1.0,
                driver=0,
                producer=-1,
                input_rx=-1.0,
                done=1.0,
                lateness=0.0,
                saddle=saddle,
                estimate=estimate,
                horse=horse,
                rider=rider,
                physics=physics,
                parts=parts,
            )
        )

    def pack_old() -> None:
        head = [7.0, 1.0, 1.0, 0.0, -1.0, -1.0, 1.0, 0.0]
        ring.write([*head, *saddle, *estimate, *horse, *rider, *physics, *parts])

    def count_new() -> None:  # the pacing counters of one tick (TickLoop._count_tick)
        counter.count_tick(0, 0, 0.0001, 0.0002, 0)

    def count_old() -> None:
        values[index["ticks"]] += 1
        values[index["overruns"]] = 0
        values[index["skipped"]] = 0
        values[index["lateness_sum"]] += 0.0001
        values[index["lateness_max"]] = max(values[index["lateness_max"]], 0.0001)
        values[index["step_max"]] = max(values[index["step_max"]], 0.0002)
        values[bucket0 + 0] += 1

    def best(fn: object) -> float:
        # CPU time of this thread (thread_time): on a host where other processes take the cores,
        # wall time counts their turns too; this counts the calls' own work.
        return min(timeit.repeat(fn, number=n, repeat=repeats, timer=time.thread_time)) / n * 1e6  # type: ignore[arg-type]

    try:
        return [
            ("pack + write a record (56+24 ch)", best(pack_new), best(pack_old)),
            ("the pacing counters of a tick", best(count_new), best(count_old)),
        ]
    finally:
        ring.close()
        shared.close()


if __name__ == "__main__":
    main()
