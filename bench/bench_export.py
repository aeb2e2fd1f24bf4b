"""``riderlive export`` of a 10-minute take, both formats, end to end as a user runs it.

    .venv/bin/python bench/bench_export.py [--minutes 10] [--rate 120]

Writes a take (a procedural canter and the rules' rider, every horse and rider
channel, as the service records it) to a temporary directory, then times
``riderlive export TAKE --format bvh`` and ``--format gltf`` in child processes. The
baseline, measured in the same run, is the per-frame path the live service uses
(``rider_pose`` + ``horse_pose`` on floats) timed on 2000 frames and scaled to the
take: what an export without the array solver would cost. Target (issue 16): each
format under 10 s for 10 minutes at 120 Hz. On a shared machine the child's CPU time
(user + system) is printed too: wall time there also counts waiting for a core.
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import polars as pl

from riderlive.channels import HORSE_NAMES, RIDER_NAMES
from riderlive.horse import DEFAULT_SCALE, generate_gait
from riderlive.rules import RiderModel
from riderlive.skeleton import horse_pose, rider_pose


def make_take(directory: Path, minutes: float, rate: float) -> tuple[Path, np.ndarray, np.ndarray]:
    horse_table = generate_gait("canter", minutes * 60.0, rate, seed=1)
    horse = np.column_stack([horse_table.column(n) for n in HORSE_NAMES])
    rider = RiderModel(scale=DEFAULT_SCALE).evaluate_batch(horse)
    t = np.arange(len(horse)) / rate
    columns = {"t": t, **dict(zip(HORSE_NAMES, horse.T, strict=True)), **dict(zip(RIDER_NAMES, rider.T, strict=True))}
    path = directory / "long.csv"
    pl.DataFrame(columns).write_csv(path)
    path.with_suffix(".json").write_text(f'{{"tick_rate": {rate}, "length_scale": 25.0}}')
    return path, horse, rider


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--rate", type=float, default=120.0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        directory = Path(tmp)
        path, horse, rider = make_take(directory, args.minutes, args.rate)
        frames = len(horse)
        print(
            f"take: {frames} frames ({args.minutes:g} min at {args.rate:g} Hz), {path.stat().st_size / 1e6:.0f} MB CSV"
        )
        sample = 2000
        start = time.perf_counter()
        for k in range(sample):
            rider_pose(rider[k].tolist())
            horse_pose(horse[k].tolist())
        per_frame = (time.perf_counter() - start) / sample
        baseline = per_frame * frames
        print(f"baseline: per-frame float solver {per_frame * 1e6:.0f} us/frame -> {baseline:.1f} s for the take")
        riderlive = str(Path(sys.executable).with_name("riderlive"))
        for fmt, out in (("bvh", directory / "long"), ("gltf", directory / "long.glb")):
            start = time.perf_counter()
            cpu_start = resource.getrusage(resource.RUSAGE_CHILDREN)
            subprocess.run([riderlive, "export", str(path), "--format", fmt, "-o", str(out)], check=True)
            seconds = time.perf_counter() - start
            cpu_end = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = (cpu_end.ru_utime - cpu_start.ru_utime) + (cpu_end.ru_stime - cpu_start.ru_stime)
            size = sum(p.stat().st_size for p in directory.glob("long.*") if p.suffix in (".bvh", ".glb"))
            verdict = "OK" if seconds < 10.0 else "OVER"
            print(
                f"export --format {fmt}: {seconds:.2f} s end to end, {cpu:.2f} s CPU ({verdict}, target < 10 s), "
                f"{baseline / seconds:.1f}x faster than the per-frame baseline; files so far {size / 1e6:.0f} MB"
            )


if __name__ == "__main__":
    main()
