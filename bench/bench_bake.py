"""``riderlive bake`` of a large take, end to end, as a user runs it, in CSV or Parquet.

    .venv/bin/python bench/bench_bake.py [--frames 1000000] [--format csv]
    .venv/bin/python bench/bench_bake.py --frames 10000000 --format parquet

Writes a horse take of N frames (t + every horse channel, uniform random values) to
a temporary file, then times ``riderlive bake IN -o OUT --timings`` in a child
process (wall clock, from start-up to exit; peak memory is the child's max RSS), and
prints the bake's own account of where its time went. The baseline, measured in the
same run, is the I/O floor: a child that only reads the same file and writes the
same number of cells back with the same library (polars) and the same options
(Parquet: no compression, statistics, row groups of ``ROW_GROUP``). For Parquet a
second floor streams the same copy (``scan_parquet`` .. ``sink_parquet``, no Python
per chunk), as the bake streams; the whole-frame floor reads it all, then writes.
Before timing, one child builds the rules kernel, so a cold numba cache (the first
bake with a preset compiles it, seconds) is not counted.

Targets: CSV, 10^6 frames: <= 15 s and <= 1.5 GB (issue 2); Parquet to Parquet,
10^7 frames: >= 5 M frames/s end to end (issue 18).
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
from riderlive.framefile import PARQUET_COMPRESSION
from riderlive.parquetstream import ROW_GROUP

FLOOR = """
import sys, numpy as np, polars as pl
src, out, width, fmt = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
if fmt == "csv":
    frame = pl.read_csv(src, infer_schema_length=0).cast(pl.Float64)
else:
    frame = pl.read_parquet(src)
data = frame.to_numpy(order="fortran")
columns = {f"c{i}": data[:, i % data.shape[1]] for i in range(width)}
if fmt == "csv":
    pl.DataFrame(columns).write_csv(out)
else:
    pl.DataFrame(columns).write_parquet(out, compression=sys.argv[5], row_group_size=int(sys.argv[6]))
"""

STREAMED_FLOOR = """
import sys, polars as pl
src, out, width, compression, row_group = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4], int(sys.argv[5])
names = pl.read_parquet_schema(src)
cols = [pl.col(list(names)[i % len(names)]).alias(f"c{i}") for i in range(width)]
pl.scan_parquet(src).select(cols).sink_parquet(out, compression=compression, statistics=True, row_group_size=row_group)
"""

WARM = """
import numpy as np
from riderlive.channels import RIDER
from riderlive.rules import RiderModel
from riderlive.rules.kuhnel2003 import RULE_INPUTS
RiderModel()._kernel()([np.zeros(10)] * len(RULE_INPUTS), np.zeros((len(RIDER), 10)))
"""

WRAPPER = """
import resource, subprocess, sys
done = subprocess.run(sys.argv[1:], check=True, capture_output=True, text=True)
sys.stderr.write(done.stderr)
print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
"""


def timed_child(args: list[str]) -> tuple[float, float, str]:
    """Wall seconds, peak RSS (MB) and stderr of one child, measured by a wrapper of its own."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", WRAPPER, *args], check=True, capture_output=True, text=True)
    elapsed = time.perf_counter() - start
    return elapsed, int(done.stdout.split()[-1]) / 1024.0, done.stderr.strip()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=1_000_000)
    parser.add_argument("--format", choices=("csv", "parquet"), default="csv")
    parser.add_argument("--rounds", type=int, default=1, help="bake and floor runs, alternating; best of each")
    args = parser.parse_args()
    subprocess.run([sys.executable, "-c", WARM], check=True)
    with tempfile.TemporaryDirectory() as tmp:
        ext = args.format
        src, out, floor_out = Path(tmp) / f"horse.{ext}", Path(tmp) / f"rider.{ext}", Path(tmp) / f"floor.{ext}"
        rng = np.random.default_rng(0)
        columns = {"t": np.arange(args.frames) / 120.0}
        columns |= {name: rng.uniform(-8.0, 8.0, args.frames) for name in HORSE_NAMES}
        frame = pl.DataFrame(columns)
        if ext == "csv":
            frame.write_csv(src)
        else:
            frame.write_parquet(src, compression=PARQUET_COMPRESSION, row_group_size=ROW_GROUP)
        del frame, columns
        print(f"input: {args.frames:,} frames, {src.stat().st_size / 1e6:.0f} MB {ext}")
        width = str(len(RIDER_NAMES) + 1)
        group = str(ROW_GROUP)
        floor_args = [sys.executable, "-c", FLOOR, str(src), str(floor_out), width, ext, PARQUET_COMPRESSION, group]
        streamed_args = [
            sys.executable,
            "-c",
            STREAMED_FLOOR,
            str(src),
            str(floor_out),
            width,
            PARQUET_COMPRESSION,
            group,
        ]
        bake_args = [sys.executable, "-m", "riderlive", "bake", str(src), "-o", str(out), "--timings"]
        floors, streamed, bakes = [], [], []
        for _ in range(args.rounds):
            floors.append(timed_child(floor_args))
            if ext == "parquet":
                streamed.append(timed_child(streamed_args))
            bakes.append(timed_child(bake_args))
        floor_s, floor_mb, _ = min(floors)
        bake_s, bake_mb, account = min(bakes)
        rate = args.frames / bake_s / 1e6
        print(f"riderlive bake: {bake_s:.2f} s end to end, {rate:.2f} M frames/s, peak RSS {bake_mb:.0f} MB")
        print(f"  its own account: {account.removeprefix('riderlive bake: ')}")
        print(f"  (the rest, {bake_s - _accounted(account):.2f} s, is start-up: interpreter, imports, kernel load)")
        print(
            f"  whole-frame read+write floor: {floor_s:.2f} s ({args.frames / floor_s / 1e6:.2f} M frames/s), "
            f"peak RSS {floor_mb:.0f} MB; ratio bake/floor = {bake_s / floor_s:.2f}"
        )
        if streamed:
            s_s, s_mb, _ = min(streamed)
            print(
                f"  streamed read+write floor: {s_s:.2f} s ({args.frames / s_s / 1e6:.2f} M frames/s), "
                f"peak RSS {s_mb:.0f} MB; ratio bake/floor = {bake_s / s_s:.2f}"
            )
        print(f"output: {out.stat().st_size / 1e6:.0f} MB")


def _accounted(account: str) -> float:
    """The seconds of the bake's --timings line (its read + rules + write)."""
    value, unit = account.split(" frames in ")[1].split(" (", maxsplit=1)[0].split()
    return float(value) / (1e3 if unit == "ms" else 1.0)


if __name__ == "__main__":
    main()
