"""Saddle estimator speed: one live estimate step, against the procedural horse's own frame.

Both measured in the same run on the same core: the procedural horse's live frame
(``ProceduralHorse.sample``, the baseline), then the estimator stepping through a
synthetic saddle recording (the same horse's saddle, with drift, noise and dropouts)
at 120 Hz and at 1000 Hz input: the median step, the mean (which carries the
analyses, 20 a second) and the 99th percentile, then an analysis alone and the
rebuilt horse frame (``rebuild.horse_frame``). Target (issue 12): a step <= 20 us
median.

Then the live service's tick (``TickCore``: input in, rules, blends, the saddle pose of
every tick) at 120 Hz with a 1000 Hz stream, driven by the horse frames of the
recording (resampled) and by its saddle samples (each stepped through the estimator,
the rebuilt horse read): per tick, the median, 99th percentile and worst; and
``saddle_pose`` alone (what every tick adds, whatever drives).

    .venv/bin/python bench/bench_saddle.py      # pinned to one core
"""

from __future__ import annotations

import os
import statistics
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

from riderlive.horse import ProceduralHorse
from riderlive.horse.script import gait_script
from riderlive.realtime.core import Mode, TickCore, Timing
from riderlive.realtime.layout import InputKind
from riderlive.realtime.saddle_input import saddle_pose
from riderlive.rules import RiderModel
from riderlive.saddle.estimator import Model, State, step
from riderlive.saddle.pose import SaddlePoint
from riderlive.saddle.rebuild import horse_frame
from riderlive.saddle.synthetic import IMU_STRAP, record

SECONDS = 60.0


def horse_frame_time(n: int = 20_000, rate: float = 1000.0) -> float:
    """Best of 5 runs of the mean live frame time (s) of the procedural trot."""
    runs = []
    for r in range(5):
        horse = ProceduralHorse("trot", seed=3)
        start = time.perf_counter()
        for i in range(n):
            horse.sample((r * n + i) / rate)
        runs.append((time.perf_counter() - start) / n)
    return min(runs)


def step_times(rate: float, model: Model) -> tuple[list[float], list[float], State]:
    """Per-step times (s) through a recording; those of the steps that ran an analysis apart."""
    rec = record(gait_script("trot", SECONDS, seed=3), rate, imperfections=IMU_STRAP, seed=1)
    assert rec.saddle.t is not None
    times, rows = rec.saddle.t.tolist(), rec.saddle.values.tolist()
    state = State()
    plain: list[float] = []
    analysed: list[float] = []
    clock = time.perf_counter_ns
    for t, row in zip(times, rows, strict=True):
        before = state.tracking.counters.analyses
        start = clock()
        state = step(model, state, t, row)
        elapsed = (clock() - start) * 1e-9
        (analysed if state.tracking.counters.analyses != before else plain).append(elapsed)
    return plain, analysed, state


def frame_time(model: Model, state: State, n: int = 20_000) -> float:
    t0 = state.t
    start = time.perf_counter()
    for i in range(n):
        horse_frame(model, state, t0 + i * 1e-5)
    return (time.perf_counter() - start) / n


def tick_times(kind: InputKind, tick_rate: float = 120.0, rate: float = 1000.0) -> list[float]:
    """Per-tick times (s) of the live tick fed a 1000 Hz trot: its horse frames, or its saddle."""
    rec = record(gait_script("trot", 20.0, seed=3), rate, imperfections=IMU_STRAP, seed=1)
    table = rec.saddle if kind is InputKind.SADDLE else rec.horse
    assert rec.saddle.t is not None
    times, rows = rec.saddle.t.tolist(), table.values.tolist()
    core = TickCore(RiderModel(scale=25.0), Timing(), ProceduralHorse("trot", seed=3), Mode.INPUT)
    out: list[float] = []
    k, clock = 0, time.perf_counter_ns
    for n in range(int(times[-1] * tick_rate)):
        now = n / tick_rate
        start = clock()
        while k < len(times) and times[k] <= now:
            core.push_input(1, times[k], times[k], rows[k], kind)
            k += 1
        core.step(now)
        out.append((clock() - start) * 1e-9)
    return out


def pose_time(n: int = 20_000) -> float:
    horse = ProceduralHorse("trot", seed=3).sample(0.3)
    point = SaddlePoint()
    start = time.perf_counter()
    for _ in range(n):
        saddle_pose(horse, 1.0, point)
    return (time.perf_counter() - start) / n


def main() -> None:
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[-1]})  # one core
    model = Model()
    step_times(120.0, model)  # warm up (templates, caches)
    horse = horse_frame_time()
    print(f"procedural horse, live trot frame (baseline): {horse * 1e6:7.2f} us")
    for rate in (120.0, 1000.0):
        plain, analysed, state = step_times(rate, model)
        every = plain + analysed
        median = statistics.median(every)
        p99 = float(np.percentile(every, 99))
        print(
            f"estimate step at {rate:4.0f} Hz input: median {median * 1e6:6.2f} us (x{median / horse:.2f} the horse's"
            f" frame), mean {statistics.fmean(every) * 1e6:6.2f} us, p99 {p99 * 1e6:7.1f} us;"
            f" {len(analysed)} analyses, median {statistics.median(analysed) * 1e6:6.0f} us,"
            f" max {max(analysed) * 1e6:6.0f} us; lock {state.lock.value}"
        )
    rebuilt = frame_time(model, state)
    print(f"rebuilt horse frame (hooves, trunk, inverse): {rebuilt * 1e6:7.2f} us  (x{rebuilt / horse:.2f})")
    print(f"saddle pose of a horse frame (every tick):     {pose_time() * 1e6:7.2f} us  (x{pose_time() / horse:.2f})")
    for kind in (InputKind.HORSE, InputKind.SADDLE):
        ticks = tick_times(kind)
        median = statistics.median(ticks)
        print(
            f"live tick at 120 Hz, 1000 Hz {kind.name.lower():6} input: median {median * 1e6:7.1f} us,"
            f" p99 {float(np.percentile(ticks, 99)) * 1e6:7.1f} us, max {max(ticks) * 1e6:7.1f} us"
        )


if __name__ == "__main__":
    main()
