"""The live saddle path against the offline bake of the same samples (issue 24), quiet or loaded.

    PYTHONPATH=$PWD .venv/bin/python bench/bench_saddle_live.py [--runs 3] [--seconds 12]
        [--sample-rate 200] [--rate 120] [--burners 2]   (both cores busy: a render host)

Starts the real ``riderlive serve`` (tick at ``--rate``, everything else its defaults) and,
per run, streams a synthetic trot's saddle samples (``saddle.synthetic.record``, clean, at
``--sample-rate``) to ``/ws/saddle`` at their own timing from a thread of this process,
while a ``/ws/rider`` client collects every frame (all rider channels, ``source_t``). The
bake: ``saddle.rebuild`` of the same samples, the server's preset's rules on each rebuilt
frame, read at each live frame's ``source_t`` (linear between samples). Compared over the
frames the saddle drove from 2 s after the first sample (the estimator locked) to the last
sample: Pearson r per rider channel that moves (std > 1e-6), the largest one-tick change
of ``lower_back.rz``'s live-minus-bake difference (the steps the issue saw, deg), the share
of frames read past the newest sample the tick had (the estimate's ``age`` over one sample
interval: extrapolated, where live and bake part), and how late this process's sender was.

Goal (issue 24): r >= 0.95 on every rider channel, on a render host (both cores busy).
No baseline code path to compare with: the bake is the reference; each figure says quiet or loaded.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import threading
import time
from pathlib import Path

import httpx
import numpy as np
from websockets.sync.client import connect

from bench import serving
from riderlive.channels import RIDER_INDEX, RIDER_NAMES
from riderlive.horse.script import gait_script
from riderlive.rules import RiderModel, load_preset
from riderlive.saddle import Model, SaddlePoint
from riderlive.saddle.rebuild import rebuild
from riderlive.saddle.synthetic import record

BACK = RIDER_INDEX["lower_back.rz"]
LOCKED_AFTER = 2.0
"""Seconds from the first sample after which frames are compared (the estimator has locked)."""


def collect(ws_url: str, frames: list[dict], stop: threading.Event) -> None:
    """Every /ws/rider frame (the default subscription: every rider channel) until ``stop``."""
    with connect(ws_url + "/ws/rider") as ws:
        ws.send(json.dumps({"type": "subscribe", "saddle": True}))
        while not stop.is_set():
            try:
                message = json.loads(ws.recv(timeout=0.5))
            except TimeoutError:
                continue
            if message.get("type") == "frame":
                frames.append(message)


def send(ws_url: str, times: np.ndarray, rows: np.ndarray, fifo: int = 0) -> float:
    """The samples at their own timing (JSON ``{"t", "v"}``), this thread at SCHED_FIFO ``fifo``
    if > 0 (a producer whose samples come on time: the service's own handling measured);
    the largest lateness of a send (s)."""
    if fifo > 0:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(fifo))  # this thread only (Linux)
    late = 0.0
    with connect(ws_url + "/ws/saddle") as ws:
        json.loads(ws.recv(timeout=5))
        start, t0 = time.perf_counter(), float(times[0])
        for t, row in zip(times.tolist(), rows.tolist(), strict=True):
            wait = start + (t - t0) - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
            late = max(late, -wait)
            ws.send(json.dumps({"t": t, "v": row}))
        time.sleep(0.3)  # the last samples read before the producer leaves
    return late


def one_run(port: int, seed: int, args: argparse.Namespace, rules: RiderModel) -> dict[str, float | str]:
    url = f"ws://127.0.0.1:{port}"
    trot = record(gait_script("trot", args.seconds, seed=seed), args.sample_rate, seed=seed)
    times, values = trot.saddle.t, trot.saddle.values
    assert times is not None
    frames: list[dict] = []
    stop = threading.Event()
    follower = threading.Thread(target=collect, args=(url, frames, stop), daemon=True)
    follower.start()
    time.sleep(0.5)  # subscribed before the first sample (a connect, not a measured wait)
    sender: list[float] = []
    thread = threading.Thread(target=lambda: sender.append(send(url, times, values, args.producer_fifo)))
    thread.start()
    thread.join()
    send_late = sender[0]
    stop.set()
    follower.join()
    baked_horse = rebuild(Model(point=SaddlePoint()), times, values).horse
    baked = np.array([rules.evaluate(frame.tolist()) for frame in baked_horse])
    live = [f for f in frames if f["driver"] == "input" and times[0] + LOCKED_AFTER <= f["source_t"] <= times[-1]]
    at = np.array([f["source_t"] for f in live])
    seq = np.array([f["seq"] for f in live])
    rider = np.array([f["values"] for f in live])
    worst, worst_r, back_r = "", 1.0, float("nan")
    for i, name in enumerate(RIDER_NAMES):
        truth = np.interp(at, times, baked[:, i])
        if truth.std() < 1e-6:
            continue
        r = float(np.corrcoef(truth, rider[:, i])[0, 1])
        if r < worst_r:
            worst, worst_r = name, r
        if i == BACK:
            back_r = r
    error = rider[:, BACK] - np.interp(at, times, baked[:, BACK])
    age = np.array([f["estimate"]["age"] if f.get("estimate") else np.nan for f in live])
    past = age > 1.0 / args.sample_rate + 1e-9
    if args.dump:
        for k in np.argsort(-np.abs(error))[:15]:
            print(f"   t {at[k] - times[0]:7.3f}  seq {seq[k]}  err {error[k]:+.3f}  age {age[k] * 1000:6.1f} ms")
    one_tick = np.abs(np.diff(error))[np.diff(seq) == 1]
    ticks = int(seq[-1] - seq[0] + 1) if len(seq) else 0
    return {
        "frames": len(live),
        "missed": 1.0 - len(live) / ticks if ticks else 1.0,
        "min_r": worst_r,
        "worst": worst,
        "back_r": back_r,
        "back_step_max": float(one_tick.max()) if len(one_tick) else float("nan"),
        "send_late_max": send_late,
        "past": float(np.mean(past)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=12.0)
    parser.add_argument("--sample-rate", type=float, default=200.0)
    parser.add_argument("--rate", type=float, default=120.0, help="the tick's rate (Hz)")
    parser.add_argument("--burners", type=int, default=0, help="normal-priority busy loops (2: both cores)")
    parser.add_argument(
        "--producer-fifo", type=int, default=0, help="the sender at SCHED_FIFO N (its samples on time under load)"
    )
    parser.add_argument("--dump", action="store_true", help="print the largest lower_back.rz errors of each run")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "service.toml"
        config.write_text(f'[server]\nlog_level = "warning"\n[tick]\nrate = {args.rate}\n')
        proc, port = serving.start_server(config, min_ticks=args.rate, timeout=180.0)  # then the burners
        try:
            measure(port, args)
        finally:
            proc.terminate()
            proc.communicate(timeout=30)


def measure(port: int, args: argparse.Namespace) -> None:
    """The runs against the server on ``port``, with ``--burners`` busy loops beside them."""
    with serving.busy_cores(args.burners) as load:
        state = httpx.get(f"http://127.0.0.1:{port}/api/state", timeout=5).json()
        rules = RiderModel(params=load_preset(state["tick"]["preset"]), scale=25.0)
        producer = f"producer at SCHED_FIFO {args.producer_fifo}" if args.producer_fifo else "producer normal"
        print(
            f"{load}, {producer}; tick {args.rate:g} Hz (realtime {state['tick'].get('realtime')}), "
            f"a {args.sample_rate:g} Hz trot of {args.seconds:g} s per run"
        )
        print("run  frames  missed  past newest  min r (channel)          lower_back.rz r  1-tick step max  send late")
        results = []
        for run in range(args.runs):
            res = one_run(port, 11 + run, args, rules)
            results.append(res)
            print(
                f"{run + 1:>3}  {res['frames']:>6}  {res['missed']:>6.1%}  {res['past']:>11.1%}  {res['min_r']:.4f} "
                f"({res['worst']:<18})  {res['back_r']:.4f}           {res['back_step_max']:.3f} deg"
                f"        {res['send_late_max'] * 1000:.1f} ms"
            )
        print(f"min r over runs: {min(float(r['min_r']) for r in results):.4f} (goal >= 0.95), {load}")


if __name__ == "__main__":
    main()
