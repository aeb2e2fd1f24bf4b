"""Fit a preset on the page: what running the fit in a child process costs, and what it costs the tick.

    .venv/bin/python bench/bench_fit_page.py [--seconds 20] [--loaded]

A canter take of ``--seconds`` with its rider recorded (english) in a fresh service's takes
directory. Printed, same run:

- the fit in this process (:func:`riderlive.service.fit_worker.run`, imports warm): what a
  worker thread in the web process would spend, holding its GIL;
- ``POST /api/takes/NAME/fit`` against the real service: the same fit in a niced child
  process, with its start and imports; the ratio of the two is the child's overhead;
- the tick's lateness (``/api/latency``, p99 and max) over an idle window and over the
  window of the fit, and the ticks the service counts as late/missed in each.

``--loaded``: two busy processes (``bench.serving.burn``) run beside it.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import httpx
import numpy as np

from bench.serving import busy_cores, start_server
from riderlive.channels import HORSE_NAMES, RIDER_NAMES
from riderlive.horse import DEFAULT_SCALE, ProceduralHorse
from riderlive.rules import RiderModel
from riderlive.rules.params import PRESET_DIR, load_preset
from riderlive.service.fit_worker import FitJob, run

RATE = 120.0


def write_take(folder: Path, name: str, seconds: float) -> Path:
    horse = ProceduralHorse("canter", 6.0, seed=2)
    rows = np.array([horse.sample(k / RATE) for k in range(int(seconds * RATE))])
    rider = RiderModel(params=load_preset("english"), scale=DEFAULT_SCALE).evaluate_batch(rows)
    t = np.arange(len(rows)) / RATE
    lines = [",".join(["t", *HORSE_NAMES, *RIDER_NAMES])]
    lines += [",".join(repr(float(v)) for v in (t[k], *rows[k], *rider[k])) for k in range(len(rows))]
    path = folder / f"{name}.csv"
    path.write_text("\n".join(lines) + "\n")
    (folder / f"{name}.json").write_text(json.dumps({"name": name, "length_scale": DEFAULT_SCALE}))
    return path


def tick_window(base: str, seconds: float) -> dict[str, float]:
    answer = httpx.get(f"{base}/api/latency", params={"window": max(1.0, min(120.0, seconds))}, timeout=10).json()
    summary = answer["histograms"]["tick_lateness"]["window"]
    return {k: summary.get(k, float("nan")) for k in ("count", "p99", "max")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--loaded", action="store_true")
    args = parser.parse_args()
    with busy_cores(2 if args.loaded else 0) as state, tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        (root / "takes").mkdir()
        (root / "presets").mkdir()
        take = write_take(root / "takes", "bench-take", args.seconds)
        config = root / "service.toml"
        config.write_text(
            '[tick]\nrealtime_priority = false\npreset_dirs = ["presets"]\n[takes]\ndirectory = "takes"\n'
        )
        proc, port = start_server(config)
        base = f"http://127.0.0.1:{port}"
        try:
            job = FitJob(
                horse=str(take), start=str(PRESET_DIR / "kuhnel2003.toml"), output=str(root / "a.toml"), name="a"
            )
            run(job)  # imports and first-use costs out of the way
            wall, cpu = time.perf_counter(), time.process_time()
            report = json.loads(run(job))
            wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
            idle_t = time.perf_counter()
            time.sleep(max(5.0, wall))  # an idle window as long as a fit, for the tick's lateness
            idle = tick_window(base, time.perf_counter() - idle_t)
            post = time.perf_counter()
            reply = httpx.post(
                f"{base}/api/takes/bench-take/fit", json={"preset": "b", "start": "kuhnel2003"}, timeout=600
            )
            post = time.perf_counter() - post
            during = tick_window(base, post)
            assert reply.status_code == 200, reply.text
            load = os.getloadavg()[0]
            print(f"bench_fit_page: a {args.seconds:g} s canter take, english rider recorded; {state}; load {load:.1f}")
            identified = sum(p["identified"] for p in report["parameters"])
            print(f"  in this process (a worker thread's cost): {wall:.2f} s wall, {cpu:.2f} s CPU; {identified} found")
            print(f"  POST /api/takes/NAME/fit (niced child process, with its imports): {post:.2f} s wall")
            print(f"  ratio POST / in-process: {post / wall:.2f}x wall")
            for label, w in (("idle", idle), ("during the fit", during)):
                print(
                    f"  tick lateness {label}: {int(w['count'])} ticks, "
                    f"p99 {w['p99'] * 1e3:.2f} ms, max {w['max'] * 1e3:.2f} ms"
                )
        finally:
            proc.terminate()
            proc.communicate(timeout=30)


if __name__ == "__main__":
    main()
