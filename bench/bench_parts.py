"""Rider parts speed: what the reins, arms and stirrups add to a live frame, against the rules.

    .venv/bin/python bench/bench_parts.py [--frames 2000] [--rounds 9]

Pinned to one core. Frames: the procedural horse (gallop, walk, canter: the neck and
head move) at 120 Hz, the rider from ``kuhnel2003`` at length scale 25. Per frame,
median over ``--rounds`` rounds that take every measurement in turn:

- baseline: ``RiderModel.evaluate`` (today's rule evaluation, the live tick's path);
- parts: what the tick adds (``TickCore._parts``: ``RiderParts.evaluate`` on the
  published rider and the finite check), the source compiled by numba as the tick runs
  it (compiled or loaded before timing, as the tick's warm-up does);
- the same, interpreted (the one source on Python floats: no numba);
- follow-through, when a preset turns it on (off in ``kuhnel2003``): one
  ``spring_step`` over the 37 rider channels (NumPy), for reference.

Target (issue 17): parts <= 5 us per live frame; the ratio to the baseline is the
figure to compare across machines (2 shared cores: absolute numbers drift).
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import time
from collections.abc import Callable

import numpy as np

from riderlive.horse import DEFAULT_SCALE, generate_gait
from riderlive.rules.animator import SpringState, spring_step
from riderlive.rules.engine import RiderModel
from riderlive.rules.params import load_preset
from riderlive.rules.parts import RiderParts


def per_frame(fn: Callable[[int], object], n: int) -> float:
    """Microseconds per call of ``fn(i)`` over ``i`` in ``range(n)``."""
    start = time.perf_counter()
    for i in range(n):
        fn(i)
    return (time.perf_counter() - start) / n * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=2000)
    parser.add_argument("--rounds", type=int, default=9)
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[-1]})  # one core
    params = load_preset("kuhnel2003")
    model = RiderModel(params, scale=DEFAULT_SCALE)
    parts = RiderParts(params)
    parts.warm()  # as the tick does before its first deadline
    interpreted = RiderParts(params, compiled=False)
    third = args.frames // 3 + 1
    takes = [generate_gait(g, third / 120.0, 120.0).values for g in ("gallop", "walk", "canter")]
    horse = [list(map(float, row)) for row in np.concatenate(takes)[: args.frames]]
    rider = [model.evaluate(h) for h in horse]
    n = len(horse)
    isfinite = math.isfinite

    def rules(i: int) -> object:
        return model.evaluate(horse[i])

    def added(i: int) -> object:
        out = parts.evaluate(horse[i], rider[i])
        return all(map(isfinite, out))

    def python(i: int) -> object:
        out = interpreted.evaluate(horse[i], rider[i])
        return all(map(isfinite, out))

    state = SpringState(np.zeros(len(rider[0])), np.zeros(len(rider[0])))
    targets = [np.asarray(r) for r in rider]

    def follow(i: int) -> object:
        return spring_step(state, targets[i], 1 / 120, 3.0, 0.4)

    results: dict[str, list[float]] = {"rules": [], "parts": [], "python": [], "follow": []}
    for _ in range(args.rounds):
        results["rules"].append(per_frame(rules, n))
        results["parts"].append(per_frame(added, n))
        results["python"].append(per_frame(python, n))
        results["follow"].append(per_frame(follow, n))
    med = {k: statistics.median(v) for k, v in results.items()}
    low = {k: min(v) for k, v in results.items()}
    high = {k: max(v) for k, v in results.items()}
    rows = (
        ("rules", "rules (RiderModel.evaluate, baseline)"),
        ("parts", "rider parts added by the tick"),
        ("python", "the same parts, interpreted"),
        ("follow", "follow-through when on (spring_step)"),
    )
    print(f"frames {n} (gallop, walk, canter at 120 Hz), rounds {args.rounds}, one core")
    for key, label in rows:
        print(f"{label:40s} {med[key]:7.2f} us/frame  [{low[key]:.2f}-{high[key]:.2f}]")
    verdict = "ok" if med["parts"] <= 5.0 else "OVER"
    print(f"parts / rules {med['parts'] / med['rules']:.2f}, parts / interpreted {med['parts'] / med['python']:.2f}")
    print(f"target parts <= 5 us: {verdict}")


if __name__ == "__main__":
    main()
