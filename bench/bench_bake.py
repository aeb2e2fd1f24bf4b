"""``riderlive bake`` of a large CSV, end to end, as a user runs it.

    .venv/bin/python bench/bench_bake.py [--frames 1000000]

Writes a horse take of N frames (t + every horse channel) to a temporary CSV, then
times ``riderlive bake IN -o OUT`` in a child process and reads its peak memory
(max RSS). The baseline, measured in the same run, is the I/O floor: a child that only
reads the same CSV and writes the same number of cells back with the same library.
Targets (issue 2): <= 15 s end to end and <= 1.5 GB peak for 1,000,000 frames.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import polars as pl

from riderlive.channels import HORSE_NAMES, RIDER_NAMES

FLOOR = """
import sys, numpy as np, polars as pl
frame = pl.read_csv(sys.argv[1], infer_schema_length=0).cast(pl.Float64)
data = frame.to_numpy()
out = np.repeat(data[:, :1], int(sys.argv[3]), axis=1)
pl.DataFrame(out, schema=[f"c{i}" for i in range(out.shape[1])]).write_csv(sys.argv[2])
"""


WRAPPER = """
import resource, subprocess, sys
subprocess.run(sys.argv[1:], check=True)
print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
"""


def timed_child(args: list[str]) -> tuple[float, float]:
    """Wall seconds and peak RSS (MB) of one child, measured by a wrapper of its own."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", WRAPPER, *args], check=True, capture_output=True, text=True)
    elapsed = time.perf_counter() - start
    return elapsed, int(done.stdout.split()[-1]) / 1024.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=1_000_000)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        src, out, floor_out = Path(tmp) / "horse.csv", Path(tmp) / "rider.csv", Path(tmp) / "floor.csv"
        rng = np.random.default_rng(0)
        data = rng.uniform(-8.0, 8.0, size=(args.frames, len(HORSE_NAMES)))
        columns = {"t": np.arange(args.frames) / 120.0, **{n: data[:, i] for i, n in enumerate(HORSE_NAMES)}}
        pl.DataFrame(columns).write_csv(src)
        print(f"input: {args.frames:,} frames, {src.stat().st_size / 1e6:.0f} MB")

        floor_s, floor_mb = timed_child(
            [sys.executable, "-c", FLOOR, str(src), str(floor_out), str(len(RIDER_NAMES) + 1)]
        )
        bake_s, bake_mb = timed_child([sys.executable, "-m", "riderlive", "bake", str(src), "-o", str(out)])
        print(f"riderlive bake: {bake_s:.2f} s end to end (target <= 15), peak RSS {bake_mb:.0f} MB (target <= 1536)")
        print(
            f"  baseline read+write floor: {floor_s:.2f} s, peak RSS {floor_mb:.0f} MB; "
            f"ratio bake/floor = {bake_s / floor_s:.2f}"
        )
        print(f"output: {out.stat().st_size / 1e6:.0f} MB")


if __name__ == "__main__":
    main()
