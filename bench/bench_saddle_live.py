"""The live saddle path against the offline bake of the same samples (issue 24), quiet or loaded.

    PYTHONPATH=$PWD .venv/bin/python bench/bench_saddle_live.py [--runs 3] [--seconds 12]
        [--sample-rate 200] [--rate 120] [--burners 2] [--producer-fifo N]

Starts the real ``riderlive serve`` (tick at ``--rate``, everything else its defaults) and,
per run, a **producer process** (a device: its own process, normal priority unless
``--producer-fifo N``) streams a synthetic trot's saddle samples (``saddle.synthetic.record``,
clean, at ``--sample-rate``) to ``/ws/saddle``, each at its own time with its own timestamp,
while a **collector process** keeps every ``/ws/rider`` frame (all rider channels,
``source_t``, the estimate) as received text with its arrival time (decoded afterwards, so
the collector does little while the run lasts). The bake: ``saddle.rebuild`` of the same
samples, the server's preset's rules on each rebuilt frame, read at each live frame's
``source_t`` (linear between samples). Compared over the frames the saddle drove from 2 s
after the first sample (the estimator locked) to the last sample: Pearson r per rider channel
that moves (std > 1e-6), the largest one-tick change of ``lower_back.rz``'s live-minus-bake
difference (deg), and the share of frames read past the newest sample the tick had (the
estimate's ``age`` over one sample interval: extrapolated, where live and bake part).

The producer's share against the service's: the producer records, per sample, when it woke
to send it against its schedule (**lateness**), how long the send took (back-pressure from
the server), and its thread's run and run-queue wait time (``/proc/thread-self/schedstat``:
time runnable but not running is the scheduler's; time running, its own CPU). Each frame's
tick time is known on the bench's clock (``perf_counter`` is ``CLOCK_MONOTONIC``, one clock
for every process; the engine's origin is the hello's ``engine_epoch``), so a frame
read past the newest sample is charged to the **producer** when the sample that would have
ended it was not yet sent at that tick, else to the **service** (sent, not yet read). The
collector's share: frames the server dropped or skipped for it (``/api/state``'s clients) and
gaps in its frames' ``seq``.

Goal (issue 24): r >= 0.95 on every rider channel, on a render host (both cores busy).
No baseline code path to compare with: the bake is the reference; each figure says quiet or loaded.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import multiprocessing as mp
import os
import tempfile
import time
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from websockets.sync.client import connect

from bench import serving
from riderlive.channels import RIDER_INDEX, RIDER_NAMES
from riderlive.horse.script import gait_script
from riderlive.realtime.saddle_input import MAX_DELAY
from riderlive.rules import RiderModel, load_preset
from riderlive.saddle import Model, SaddlePoint
from riderlive.saddle.rebuild import rebuild
from riderlive.saddle.synthetic import record

BACK = RIDER_INDEX["lower_back.rz"]
LOCKED_AFTER = 2.0
"""Seconds from the first sample after which frames are compared (the estimator has locked)."""
ON_TIME = 0.05
"""A producer later than this (s) is not on time (the brief's bound: 50 ms)."""
MIN_FRAMES = 120
"""Fewer compared frames (1 s at 120 Hz) than this: no r is taken (nan, "too few frames")."""
LEAD_IN = 0.2
"""Seconds from the producer's connect to its first sample (the schedule's origin)."""


def schedstat() -> tuple[float, float]:
    """This thread's time on a CPU and waiting on a run queue so far (s; zeros without procfs)."""
    try:
        with open("/proc/thread-self/schedstat") as f:
            run, wait, _ = f.read().split()
    except OSError:
        return 0.0, 0.0
    return int(run) / 1e9, int(wait) / 1e9


def produce(url: str, times: np.ndarray, rows: np.ndarray, fifo: int, out: Connection) -> None:
    """The producer process: each sample (JSON ``{"t", "v"}``, ``t`` the device's own sample time)
    sent at its time on this process's schedule; sends back, per sample, the schedule, when it
    woke to send and when the send returned, and its thread's CPU and run-queue time at both (s)."""
    if fifo > 0:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(fifo))
    n = len(times)
    woke, sent, cpu_woke, queued_woke, cpu_sent, queued_sent = (np.zeros(n) for _ in range(6))
    with connect(url + "/ws/saddle") as ws:
        json.loads(ws.recv(timeout=5))
        start, t0 = time.perf_counter() + LEAD_IN, float(times[0])
        due = start + (times - t0)
        for k, (t, row) in enumerate(zip(times.tolist(), rows.tolist(), strict=True)):
            wait = due[k] - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
            woke[k] = time.perf_counter()
            cpu_woke[k], queued_woke[k] = schedstat()
            ws.send(json.dumps({"t": t, "v": row}))
            sent[k] = time.perf_counter()
            cpu_sent[k], queued_sent[k] = schedstat()
        time.sleep(MAX_DELAY + 0.1)  # the last samples read before the producer leaves (gone: a new stream)
        segments = 0  # the service's replies so far: a "segment" is a new stream for the tick
        with contextlib.suppress(TimeoutError):
            while True:
                segments += json.loads(ws.recv(timeout=0)).get("type") == "segment"
    out.send(
        {
            "segments": segments,
            "due": due,
            "woke": woke,
            "sent": sent,
            "cpu_woke": cpu_woke,
            "queued_woke": queued_woke,
            "cpu_sent": cpu_sent,
            "queued_sent": queued_sent,
        }
    )


def collect(url: str, stop: Any, out: Connection) -> None:
    """The collector process: every /ws/rider frame (every rider channel, the saddle block) as
    received text with its arrival (``perf_counter``) until ``stop``; tells ``out`` "ready" once
    frames carry the saddle block, then sends ``(hello, hello arrival, frames)``."""
    frames: list[tuple[float, str]] = []
    with connect(url + "/ws/rider") as ws:
        hello_text = ws.recv(timeout=5)
        hello_at = time.perf_counter()
        ws.send(json.dumps({"type": "subscribe", "saddle": True}))
        ready = False
        while not stop.is_set():
            try:
                text = ws.recv(timeout=0.2)
            except TimeoutError:
                continue
            frames.append((time.perf_counter(), str(text)))
            if not ready and '"estimate"' in text:
                ready = True
                out.send("ready")
    out.send((json.loads(hello_text), hello_at, frames))


def lateness_figures(log: dict[str, np.ndarray]) -> dict[str, float]:
    """The producer's lateness per sample (woke - due) and where its time went: on a run queue
    between a send and the next wake-up (the scheduler's), during sends (CPU, run queue, and
    blocked: neither, the socket full, the server not reading), and its CPU per sample."""
    late = log["woke"] - log["due"]
    send = log["sent"] - log["woke"]
    send_cpu = log["cpu_sent"] - log["cpu_woke"]
    send_queued = log["queued_sent"] - log["queued_woke"]
    blocked = np.maximum(0.0, send - send_cpu - send_queued)
    wake_queued = log["queued_woke"][1:] - log["queued_sent"][:-1]
    return {
        "segments": int(log["segments"]),
        "late_p50": float(np.median(late)),
        "late_p99": float(np.percentile(late, 99)),
        "late_max": float(late.max()),
        "late_share": float(np.mean(late > ON_TIME)),
        "too_late_share": float(np.mean(late > MAX_DELAY)),
        "send_max": float(send.max()),
        "blocked": float(blocked.sum()),
        "blocked_max": float(blocked.max()),
        "cpu": float(log["cpu_sent"][-1] - log["cpu_woke"][0]),
        "queued": float(log["queued_sent"][-1] - log["queued_woke"][0]),
        "queued_max": float(max(wake_queued.max(initial=0.0), send_queued.max())),
    }


def share(flags: np.ndarray) -> float:
    """The share of true flags (nan of none)."""
    return float(flags.mean()) if len(flags) else float("nan")


def client_counts(port: int) -> dict[str, int]:
    """The /ws/rider client's ``dropped`` and ``skipped`` frames so far (the bench's is the only one)."""
    state = httpx.get(f"http://127.0.0.1:{port}/api/state", timeout=10).json()
    clients = state.get("clients") or []
    return {k: sum(int(c[k]) for c in clients) for k in ("dropped", "skipped")}


def one_run(port: int, seed: int, args: argparse.Namespace, rules: RiderModel) -> dict[str, Any]:
    url = f"ws://127.0.0.1:{port}"
    trot = record(gait_script("trot", args.seconds, seed=seed), args.sample_rate, seed=seed)
    times, values = trot.saddle.t, trot.saddle.values
    assert times is not None
    context = mp.get_context("spawn")  # neither inherits the bench's threads or scheduling
    stop = context.Event()
    got_frames, give_frames = context.Pipe(duplex=False)
    got_log, give_log = context.Pipe(duplex=False)
    collector = context.Process(target=collect, args=(url, stop, give_frames), daemon=True)
    collector.start()
    if not got_frames.poll(60) or got_frames.recv() != "ready":
        raise RuntimeError("the collector got no saddle frame in 60 s")
    before = client_counts(port)
    producer = context.Process(target=produce, args=(url, times, values, args.producer_fifo, give_log), daemon=True)
    producer.start()
    if not got_log.poll(args.seconds + 120):
        raise RuntimeError("the producer did not finish")
    log: dict[str, np.ndarray] = got_log.recv()
    producer.join()
    after = client_counts(port)
    stop.set()
    hello, _, raw = got_frames.recv()
    collector.join()
    frames = [(at, json.loads(text)) for at, text in raw]
    frames = [(at, f) for at, f in frames if f.get("type") == "frame"]
    origin = hello["engine_epoch"]  # engine time 0 on this clock (CLOCK_MONOTONIC, the same host)
    baked_horse = rebuild(Model(point=SaddlePoint()), times, values).horse
    baked = np.array([rules.evaluate(frame.tolist()) for frame in baked_horse])
    live = [f for _, f in frames if f["driver"] == "input" and times[0] + LOCKED_AFTER <= f["source_t"] <= times[-1]]
    compared = len(live)
    if compared < MIN_FRAMES:  # the producer so late that the saddle hardly drove: no r to take
        live = []
    at = np.array([f["source_t"] for f in live])
    seq = np.array([f["seq"] for f in live], dtype=int)
    rider = np.array([f["values"] for f in live]).reshape(len(live), len(RIDER_NAMES))
    worst, worst_r, back_r = ("", 1.0, float("nan")) if live else ("too few frames", float("nan"), float("nan"))
    for i, name in enumerate(RIDER_NAMES):
        truth = np.interp(at, times, baked[:, i])
        if not live or truth.std() < 1e-6:
            continue
        r = float(np.corrcoef(truth, rider[:, i])[0, 1])
        if r < worst_r:
            worst, worst_r = name, r
        if i == BACK:
            back_r = r
    error = rider[:, BACK] - np.interp(at, times, baked[:, BACK])
    age = np.array(
        [f["estimate"]["age"] if f.get("estimate") and f["estimate"]["age"] is not None else np.nan for f in live]
    )
    interval = 1.0 / args.sample_rate
    past = age > interval + 1e-9
    # The sample that would have ended a read past the newest: the first not before the read
    # less one interval; sent after the tick that read, the producer's share.
    tick_at = origin + np.array([f["t"] for f in live])
    needed = np.minimum(np.searchsorted(times, at - interval - 1e-9), len(times) - 1)
    unsent = log["sent"][needed] > tick_at
    if args.dump:
        for k in np.argsort(-np.abs(error))[:15]:
            print(f"   t {at[k] - times[0]:7.3f}  seq {seq[k]}  err {error[k]:+.3f}  age {age[k] * 1000:6.1f} ms")
    one_tick = np.abs(np.diff(error))[np.diff(seq) == 1]
    all_seq = np.array([f["seq"] for _, f in frames])
    return {
        "frames": compared,
        "seq_gaps": int(np.sum(np.diff(all_seq) - 1)) if len(all_seq) > 1 else 0,
        "dropped": after["dropped"] - before["dropped"],
        "skipped": after["skipped"] - before["skipped"],
        "min_r": worst_r,
        "worst": worst,
        "back_r": back_r,
        "back_step_max": float(one_tick.max()) if len(one_tick) else float("nan"),
        "past": share(past),
        "past_producer": share(past & unsent),
        "past_service": share(past & ~unsent),
        **lateness_figures(log),
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
        print(
            "run  load   frames  seq gaps/dropped/skipped  min r (channel)            lower_back.rz r  1-tick step"
            "  past newest (producer / service)"
        )
        print("     producer: late p50 / p99 / max, > 50 ms, > MAX_DELAY; send max (blocked); CPU, run-queue wait")
        results = []
        for run in range(args.runs):
            res = one_run(port, 11 + run, args, rules)
            res["load"] = os.getloadavg()[0]
            results.append(res)
            print(
                f"{run + 1:>3}  {res['load']:>4.1f}  {res['frames']:>6}  {res['seq_gaps']:>3} / {res['dropped']} / "
                f"{res['skipped']:<12}  {res['min_r']:.4f} ({res['worst']:<18})  {res['back_r']:.4f}           "
                f"{res['back_step_max']:.3f} deg  {res['past']:.1%} ({res['past_producer']:.1%} / "
                f"{res['past_service']:.1%}); {res['segments']} segments"
            )
            print(
                f"     producer: late {res['late_p50'] * 1e3:.1f} / {res['late_p99'] * 1e3:.1f} / "
                f"{res['late_max'] * 1e3:.1f} ms, {res['late_share']:.1%} > 50 ms, {res['too_late_share']:.1%} > "
                f"{MAX_DELAY * 1e3:.0f} ms; send max {res['send_max'] * 1e3:.1f} ms "
                f"(blocked {res['blocked'] * 1e3:.0f} ms, "
                f"{res['blocked_max'] * 1e3:.1f} max); CPU {res['cpu'] * 1e3:.0f} ms, "
                f"run-queue wait {res['queued'] * 1e3:.0f} ms ({res['queued_max'] * 1e3:.1f} max)"
            )
        taken = [float(r["min_r"]) for r in results if not np.isnan(r["min_r"])]
        print(
            f"min r over runs: {min(taken, default=float('nan')):.4f} (goal >= 0.95; "
            f"{len(results) - len(taken)} runs with too few frames); producer late max "
            f"{max(float(r['late_max']) for r in results) * 1e3:.0f} ms; {load}, load average "
            f"{min(r['load'] for r in results):.1f}-{max(r['load'] for r in results):.1f}"
        )


if __name__ == "__main__":
    main()
