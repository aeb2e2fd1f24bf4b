"""Procedural horse speed: batch frames per second and one live frame, each against a baseline.

Baselines, measured in the same run on the same machine: for the batch, a trivial
"horse" of 23 sinusoids over the same time array (NumPy); for the live frame, the
same 23 sinusoids on Python floats. The ratio says what the real generator (support
profiles, Hermite transfers, closed-form ramps, blends) costs over the least a
generator can do. Targets (issue 3): batch >= 1,000,000 frames/s, live <= 20 us.

    .venv/bin/python bench/bench_horse.py      # pinned to one core
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

from riderlive.channels import HORSE
from riderlive.configfile import CONFIG_DIR
from riderlive.horse import ProceduralHorse, generate, generate_gait, load_script

N_BATCH = 1_000_000
RATE = 1000.0


def best_of(fn: Callable[[], object], repeat: int = 5) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def baseline_batch() -> np.ndarray:
    t = np.arange(N_BATCH) / RATE
    out = np.empty((N_BATCH, len(HORSE)))
    for c in range(len(HORSE)):
        out[:, c] = 0.1 * np.sin(2.0 * np.pi * 1.1 * t + c)
    return out


def baseline_frame(t: float) -> list[float]:
    w = 2.0 * math.pi * 1.1 * t
    return [0.1 * math.sin(w + c) for c in range(23)]


def per_frame(sample: Callable[[float], object], n: int = 20_000, dt: float = 1.0 / RATE, t0: float = 0.0) -> float:
    """Best of 5 runs of the mean time per frame (s): the least disturbed by other load."""
    runs = []
    for r in range(5):
        start = time.perf_counter()
        base = t0 + r * n * dt
        for i in range(n):
            sample(base + i * dt)
        runs.append((time.perf_counter() - start) / n)
    return min(runs)


def main() -> None:
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[-1]})  # one core
    seconds = N_BATCH / RATE
    base_batch = best_of(baseline_batch)
    gait_batch = best_of(lambda: generate_gait("trot", seconds, RATE))
    shot = load_script(CONFIG_DIR / "shots" / "ramp.toml")
    shot_frames = round(shot.duration * RATE * 10)
    shot_batch = best_of(lambda: generate(shot, RATE * 10))
    print(f"batch baseline (23 sinusoids, NumPy): {N_BATCH / base_batch / 1e6:6.2f} M frames/s")
    print(
        f"batch trot, {N_BATCH} frames:        {N_BATCH / gait_batch / 1e6:6.2f} M frames/s"
        f"  (x{gait_batch / base_batch:.1f} the baseline's time)"
    )
    print(
        f"batch ramp.toml (7 gaits, seeded):  {shot_frames / shot_batch / 1e6:6.2f} M frames/s"
        f"  ({shot_frames} frames, x{(shot_batch / shot_frames) / (base_batch / N_BATCH):.1f})"
    )

    base_live = per_frame(baseline_frame)
    trot = ProceduralHorse("trot")
    live_trot = per_frame(trot.sample)
    seeded = ProceduralHorse("gallop", seed=3)
    live_seeded = per_frame(seeded.sample)

    def blending(t: float) -> object:  # a gait change every second: ~70 % of the frames blend two gaits
        if int(t) != int(t - 1.0 / RATE):
            blender.set_gait("canter" if blender.gait == "trot" else "trot")
        return blender.sample(t)

    blender = ProceduralHorse("trot")
    live_blend = per_frame(blending)
    mover = ProceduralHorse("canter")
    mover.sample(0.0)
    mover.perform("jump")
    live_move = per_frame(mover.sample, n=2_000, dt=0.0005)
    print(f"live baseline (23 sinusoids, floats): {base_live * 1e6:6.2f} us/frame")
    for label, value in (
        ("live trot", live_trot),
        ("live gallop, seeded variation", live_seeded),
        ("live trot<->canter every 1 s (blends)", live_blend),
        ("live jump", live_move),
    ):
        print(f"{label + ':':37s} {value * 1e6:6.2f} us/frame  (x{value / base_live:.1f})")


if __name__ == "__main__":
    main()
