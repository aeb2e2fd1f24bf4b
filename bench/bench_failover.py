"""Warm failover of the tick, timed at a /ws/rider client (docs/performance.md, "Failover").

Runs the real ``riderlive serve`` (120 Hz, no device, the tick at its documented priority)
with a producer driving /ws/horse at 120 Hz (a smooth motion, in a process of its own)
and a /ws/rider client in a thread, applies run-time settings (a preset, an animator
offset), then:

1. ``--kills`` x ``kill -9`` of the tick: kill to the first new frame at the client;
2. ``--stops`` x SIGSTOP of the tick, held 2 s: stop to the first new frame, against the
   hang threshold + 50 ms;
3. ``--stalls`` x SIGSTOP/SIGCONT for 20, 50, 100, 300 ms each: the output gap at the
   client against the stall + 2 ticks, and the failovers each cost (0 below the threshold,
   never more than 1).

Before each kill or stop it waits for a warm spare and 3.5 s of ticking (past the new
tick's warm-up leniency). After each failover it checks the settings (preset, animator
offsets) and measures the largest rider step across the handover against the largest
per-tick step of the second before (its slew; <= 1 is "no jump larger than one tick's").

Each failover is split where its time goes (the supervisor's ``last_down_at`` and
``promoted_at``, the first new frame's engine time, its arrival): kill -> found dead or hung,
-> the spare told to take over, -> its first tick, -> at the client (the web process's
forward and the client's own wake-up).

    python bench/bench_failover.py [--burners 2] [--kills 20] [--stops 20] [--stalls 10]
        [--web-priority 10] [--client-priority 0]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import multiprocessing
import os
import re
import signal
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from websockets.sync.client import connect

from bench.serving import burn, start_server
from tests.service.producers import Follower

RATE = 120.0
STALLS = (0.02, 0.05, 0.1, 0.3)


def produce(url: str, stop_at: float) -> None:
    """A producer at 120 Hz in its own process: a smooth trot-like motion; it reads what the
    service tells it (a thread) and connects again if the service drops it (counted)."""
    t0 = time.perf_counter()
    n = drops = 0
    while time.perf_counter() < stop_at:
        try:
            with connect(url + "/ws/horse", ping_interval=None) as ws:  # a stalled host must not end it
                ws.recv()
                threading.Thread(target=lambda: [None for _ in ws], daemon=True).start()
                while time.perf_counter() < stop_at:
                    n += 1
                    time.sleep(max(0.0, t0 + n / RATE - time.perf_counter()))
                    t = time.perf_counter() - t0
                    pitch, heave = 3.0 * math.sin(2 * math.pi * 1.6 * t), 0.2 * math.sin(6.4 * t)
                    values = {"rearPivot.rz": pitch, "rearPivot.ty": heave, "lfHoof.ty": 0.1}
                    ws.send(json.dumps({"t": t, "values": values}))
        except Exception as exc:
            drops += 1
            print(f"producer: dropped ({exc}); connecting again ({drops})", flush=True)
            n = int((time.perf_counter() - t0) * RATE)


class Client(Follower):
    """Every /ws/rider frame (tests/service/producers.Follower: arrival ``at``, engine time
    ``t``, its tick on this process's clock ``ticked``, rider ``values``)."""

    def __init__(self, url: str) -> None:
        super().__init__(url, horse_channels=None, max_size=None, ping_interval=None)

    def first_after(self, at: float, timeout: float = 30.0) -> tuple[int, float]:
        """Index and arrival of the first frame ticked after ``at`` (perf_counter s): a frame
        the stopped or killed tick wrote before but that arrives after is not one."""
        start = max(0, len(self.frames) - 50)
        self.inbox.wait_for(lambda f: f["ticked"] > at, timeout, start)
        i = self.first_ticked_after(at, start)
        assert i is not None
        return i, self.frames[i]["at"]


class Bench:
    def __init__(self, port: int) -> None:
        self.http = httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=10)
        self.client = Client(f"ws://127.0.0.1:{port}")
        self.lost = 0
        self.steps: list[float] = []
        self.marks: list[tuple[float, float, float, int]] = []
        """Per failover: the signal, found, spare told (perf_counter s) and the first new frame's index."""

    def supervision(self) -> dict[str, Any]:
        result: dict[str, Any] = self.http.get("/api/devices").json()["supervision"]
        return result

    def settle(self) -> dict[str, Any]:
        """Until a warm spare waits and the serving tick is past its warm-up."""
        deadline = time.perf_counter() + 600
        while time.perf_counter() < deadline:
            s = self.supervision()
            if s["up"] and s["spare"]["state"] == "warm" and (s["down_since"] is None):
                last = s["last_down_at"] or 0.0
                if time.perf_counter() - last > 3.5 + (s["last_outage"] or 0.0):
                    return s
            time.sleep(0.1)
        raise RuntimeError("no warm spare in 10 min")

    def check_settings(self, generation: int) -> None:
        deadline = time.perf_counter() + 30
        while self.supervision()["generation"] < generation or not self.supervision()["up"]:
            if time.perf_counter() > deadline:
                raise RuntimeError("no new generation")
            time.sleep(0.05)
        state = self.http.get("/api/state").json()
        tick_preset = state["tick"].get("preset")
        deadline = time.perf_counter() + 5
        while tick_preset != "child" and time.perf_counter() < deadline:  # the new generation's first status
            time.sleep(0.02)
            tick_preset = self.http.get("/api/state").json()["tick"].get("preset")
        animator = self.http.get("/api/animator").json()
        if state["preset"] != "child" or tick_preset != "child" or animator["offsets"] != {"head.rz": 3.0}:
            self.lost += 1

    def step_ratio(self, before: int, after: int) -> float:
        """Largest |step| across the handover over the largest per-tick step of the second before."""
        frames = self.client.frames
        window = np.array([f["values"] for f in frames[max(0, before - int(RATE)) : before + 1]])
        slew = np.abs(np.diff(window, axis=0)).max(axis=0)
        step = np.abs(np.subtract(frames[after]["values"], frames[before]["values"]))
        moving = slew > 1e-9
        return float((step[moving] / slew[moving]).max()) if moving.any() else 0.0

    def failover(self, sig: signal.Signals, hold: float) -> float:
        s = self.settle()
        pid = s["tick_pid"]
        at = time.perf_counter()
        os.kill(pid, sig)
        after, arrival = self.client.first_after(at)
        before = after - 1
        if hold:
            time.sleep(max(0.0, at + hold - time.perf_counter()))
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGCONT)
        self.check_settings(s["generation"] + 1)
        now = self.supervision()
        self.marks.append((at, now["last_down_at"], now["promoted_at"], after))
        self.steps.append(self.step_ratio(before, after))
        print(f"{sig.name}: first new frame at the client after {(arrival - at) * 1000:.1f} ms", flush=True)
        return arrival - at

    def stall(self, hold: float) -> tuple[float, float, int]:
        s = self.settle()
        restarts = s["restarts"]
        pid = s["tick_pid"]
        at = time.perf_counter()
        os.kill(pid, signal.SIGSTOP)
        time.sleep(hold)  # the injected stall itself
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGCONT)
        time.sleep(1.0)
        window = [(f["at"], f["t"]) for f in self.client.frames if at - 0.2 < f["at"] < at + hold + 0.8]
        arrivals = [a for a, _ in window]
        ticked = sorted(t for _, t in window)
        gap = float(np.diff(arrivals).max()) if len(arrivals) > 1 else math.inf
        tick_gap = float(np.diff(ticked).max()) if len(ticked) > 1 else math.inf
        return gap, tick_gap, self.supervision()["restarts"] - restarts


def quantiles(values: list[float]) -> str:
    a = np.array(values) * 1000
    return f"p50 {np.percentile(a, 50):.1f}, p99 {np.percentile(a, 99):.1f}, max {a.max():.1f} ms (n={len(a)})"


def stage_table(marks: list[tuple[float, float, float, int]], frames: list[dict[str, Any]]) -> str:
    """Signal -> found, -> spare told, -> its first tick, -> at the client (ms); a frame's tick
    on our clock is its ``ticked`` (engine time plus the hello's ``engine_epoch``)."""
    stages = []
    for at, found, promoted, after in marks:
        arrival, ticked = frames[after]["at"], frames[after]["ticked"]
        stages.append((found - at, promoted - found, ticked - promoted, arrival - ticked))
    names = ("found", "spare told", "first tick", "at the client")
    a = np.array(stages) * 1000
    return "; ".join(
        f"{name} p50 {np.percentile(a[:, i], 50):.1f} p99 {np.percentile(a[:, i], 99):.1f} max {a[:, i].max():.1f}"
        for i, name in enumerate(names)
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--burners", type=int, default=0, help="busy processes at normal priority (2: both cores)")
    parser.add_argument("--kills", type=int, default=20)
    parser.add_argument("--stops", type=int, default=20)
    parser.add_argument("--stalls", type=int, default=10, help="per stall length")
    parser.add_argument("--spare-nice", type=int, default=10, help="tick.spare_nice (lower: the spare warms sooner)")
    parser.add_argument(
        "--web-priority", type=int, default=None, help="server.realtime_priority (unset: the default; 0: off)"
    )
    parser.add_argument(
        "--client-priority",
        type=int,
        default=0,
        help="SCHED_FIFO of the measuring client (0: normal, beside the burners)",
    )
    args = parser.parse_args()
    if args.client_priority:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(args.client_priority))
    context = multiprocessing.get_context("spawn")
    workdir = Path(tempfile.mkdtemp(prefix="bench-failover-"))
    config = workdir / "service.toml"
    server = "" if args.web_priority is None else f"[server]\nrealtime_priority = {args.web_priority}\n"
    config.write_text(f"{server}[tick]\nrate = {RATE}\nspare_nice = {args.spare_nice}\n")
    proc, port = start_server(config)  # then the burners: a start that fails leaves none behind
    burners = [context.Process(target=burn, args=(time.perf_counter() + 7200,)) for _ in range(args.burners)]
    for burner in burners:
        burner.start()
    producer = context.Process(target=produce, args=(f"ws://127.0.0.1:{port}", time.perf_counter() + 7200))
    producer.start()
    try:
        bench = Bench(port)
        bench.http.put("/api/preset", json={"name": "child"}).raise_for_status()
        bench.http.put("/api/animator", json={"offsets": {"head.rz": 3.0}, "gains": {}}).raise_for_status()
        threshold = bench.settle()["hang_threshold"]
        kills = [bench.failover(signal.SIGKILL, 0.0) for _ in range(args.kills)]
        kill_steps, bench.steps = bench.steps, []
        kill_marks, bench.marks = bench.marks, []
        stops = [bench.failover(signal.SIGSTOP, 2.0) for _ in range(args.stops)]
        stop_steps = bench.steps
        stalls = {hold: [bench.stall(hold) for _ in range(args.stalls)] for hold in STALLS}
        final = bench.supervision()
    finally:
        producer.kill()
        proc.send_signal(signal.SIGINT)
        try:
            _, log = proc.communicate(timeout=20)
        except Exception:
            proc.kill()
            log = ""
        for burner in burners:
            burner.kill()
    load = "loaded: both cores busy with burners" if args.burners >= 2 else f"{args.burners} burner(s)"
    print(
        f"bench_failover: 120 Hz, a producer at 120 Hz, {load}; load average {os.getloadavg()[0]:.1f};"
        f" spare warm-up at nice {args.spare_nice}; web process realtime_priority {final['web_priority']};"
        f" client {'SCHED_FIFO ' + str(args.client_priority) if args.client_priority else 'normal priority'}"
    )
    print(f"hang threshold {threshold * 1000:.1f} ms")
    if kills:
        print(f"kill -9 -> first new frame at the client: {quantiles(kills)} (goal p99 <= 50 ms)")
        print(f"  largest rider step across the handover / one tick's slew: max {max(kill_steps):.2f}")
        print(f"  stages (ms): {stage_table(kill_marks, bench.client.frames)}")
    if stops:
        print(f"SIGSTOP -> first new frame: {quantiles(stops)} (goal <= {threshold * 1000 + 50:.0f} ms)")
        print(f"  largest rider step across the handover / one tick's slew: max {max(stop_steps):.2f}")
        print(f"  stages (ms): {stage_table(bench.marks, bench.client.frames)}")
    print(f"settings lost: {bench.lost} of {args.kills + args.stops} failovers")
    took = [float(m) / 1000 for m in re.findall(r"took over in ([0-9.]+) ms", log)]
    if took:
        print(f"the spare's own takeover (TakeOver received -> loop about to run): {quantiles(took)}")
    for hold, results in stalls.items():
        if not results:
            continue
        gaps = [g for g, _, _ in results]
        ticked = [g for _, g, _ in results]
        failovers = [r for _, _, r in results]
        goal = hold + 2.0 / RATE
        print(
            f"stall {hold * 1000:.0f} ms: output gap at the client max {max(gaps) * 1000:.1f} ms"
            f" (goal <= {goal * 1000:.0f}, over {sum(g > goal for g in gaps)}/{len(gaps)}), between the ticks' own"
            f" times max {max(ticked) * 1000:.1f} ms (over {sum(g > goal for g in ticked)}/{len(ticked)});"
            f" failovers {sum(failovers)} (per stall max {max(failovers)})"
        )
    print(
        f"supervision: restarts {final['restarts']}, deaths {final['deaths']}, hangs {final['hangs']},"
        f" stalls excused {final['stalls']}, device waits excused {final.get('io_waits_excused', 0)},"
        f" warm takeovers {final['takeovers']}, spares {final['spare']}"
    )
    if final.get("last_hang"):
        print(f"last hang: {final['last_hang']}")


if __name__ == "__main__":
    main()
