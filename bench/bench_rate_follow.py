"""How soon the clock mapping follows a producer whose clock changes rate (offline, pure).

A producer at 120 frames a second (2 ms late plus an exponential jitter of mean 3 ms) runs
at our rate for ``--before`` s, then ``rate`` x ours; a :class:`~riderlive.realtime.resample.ClockMap`
takes every frame as it would arrive and is read 60 times a second. Printed per case, over
``--streams`` seeds: the seconds from the change until the rate in use came within 10 % of
the change and stayed there (min / median / max). The baseline in the same run: the
"before 2 s" row, the shortest baseline a stream has when its rate changes.

    PYTHONPATH=$PWD .venv/bin/python bench/bench_rate_follow.py [--streams 30]

docs/protocol.md "Clocks that drift" and docs/performance.md.
"""

from __future__ import annotations

import argparse
import statistics

import numpy as np

from riderlive.realtime.resample import ClockMap


def followed(seed: int, before: float, rate: float, after: float = 10.0, hz: float = 120.0) -> float | None:
    """Seconds from the change until the rate in use stays within 10 % of the change (None: not in ``after``)."""
    rng = np.random.default_rng(seed)
    n = int((before + after) * hz)
    sent = np.arange(n) / hz
    stamps = 1000.0 + np.where(sent < before, sent, before + rate * (sent - before))
    received = np.maximum.accumulate(sent + 0.002 + rng.exponential(0.003, n))
    change = 1.0 / rate - 1.0
    clock, k, out = ClockMap(256), 0, None
    for now in np.arange(0.0, before + after, 1.0 / 60.0):
        while k < n and received[k] <= now:
            clock.push(float(stamps[k]), float(received[k]))
            k += 1
        if now > before:
            close = abs((clock.rate - 1.0) / change - 1.0) <= 0.1
            out = (out if out is not None else now - before) if close else None
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--streams", type=int, default=30)
    args = parser.parse_args()
    rows = []
    for before in (2.0, 12.0, 30.0):
        for rate in (1.05, 0.95):
            times = [followed(seed, before, rate) for seed in range(args.streams)]
            got = [t for t in times if t is not None]
            rows.append((before, rate, got, len(times) - len(got)))
            print(
                f"before {before:4.0f} s, clock x{rate:.2f}: followed in min {min(got):.2f} / "
                f"median {statistics.median(got):.2f} / max {max(got):.2f} s"
                f"{f', not within 10 s: {len(times) - len(got)}' if len(got) < len(times) else ''}"
            )
    base = {rate: statistics.median(got) for before, rate, got, _ in rows if before == 2.0}
    for before, rate, got, _ in rows:
        ratio = statistics.median(got) / base[rate]
        print(f"median ratio to 'before 2 s', x{rate:.2f}, before {before:.0f} s: {ratio:.2f}")


if __name__ == "__main__":
    main()
