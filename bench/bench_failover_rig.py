"""Warm failover with a rig armed and moving, timed at a /ws/rider client (docs/performance.md,
"Failover with an armed rig").

Runs the real ``riderlive serve`` (100 Hz, the bench3 rig with its 2 s park on
``riderlive servo-emu`` over a pty, the real dynamixel-sdk) with a producer driving
/ws/horse and a /ws/rider client (``bench_failover.py``'s), then ``--kills`` times: arm the
rig, wait for it running and a warm spare, ``kill -9`` the tick, and time

- kill -> the first frame ticked by the new generation at the client;
- kill -> the rig ``disarmed`` again under the new generation (the guardian's park, its
  hand-back, the new generation's connect).

``--baseline-root /work/main`` runs the same case on that checkout first, in the same run
(main waits for the guardian's whole park before promoting the spare).

    python bench/bench_failover_rig.py [--burners 2] [--kills 5] [--baseline-root /work/main]
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx

from bench.bench_failover import Bench, produce, quantiles
from bench.serving import ROOT, burn, start_server

TOKEN = "bench-failover-rig"
AUTH = {"Authorization": f"Bearer {TOKEN}"}


def rig_file(workdir: Path) -> Path:
    """bench3 (its 2 s park) with generous bus budgets and a short soft start (a loaded host)."""
    text = (ROOT / "config" / "rigs" / "bench3.toml").read_text()
    for key, value in (("reply_budget_s", "0.3"), ("bus_watchdog_ms", "600"), ("soft_start_s", "0.3")):
        text = re.sub(rf"^{key} = .*$", f"{key} = {value}", text, flags=re.M)
    text = text.replace("[bus]\n", "[bus]\ntimeout_margin_ms = 40.0\n", 1)
    path = workdir / "bench3.toml"
    path.write_text(text)
    return path


def emulator(rig: Path, root: Path) -> tuple[subprocess.Popen[str], str]:
    """``riderlive servo-emu --rig RIG`` of ``root`` in its own process (SCHED_FIFO 30 where
    ``chrt`` may: real servos answer whatever the host's load), and its pty."""
    fifo = ["chrt", "-f", "30"] if shutil.which("chrt") else []  # hardware is not starved by the host's load
    emu = subprocess.Popen(
        [*fifo, sys.executable, "-m", "riderlive", "servo-emu", "--rig", str(rig)],
        stdout=subprocess.PIPE,
        text=True,
        cwd=root,
        env={**os.environ, "PYTHONPATH": str(root)},
    )
    assert emu.stdout is not None
    port = next(m.group(1) for line in emu.stdout if (m := re.match(r"port: (\S+)", line)))
    return emu, port


def wait(what: Any, timeout: float, poll: float = 0.01) -> float:
    deadline = time.perf_counter() + timeout
    while not what():
        if time.perf_counter() > deadline:
            raise RuntimeError(f"timed out after {timeout} s")
        time.sleep(poll)
    return time.perf_counter()


def run(root: Path, kills: int) -> tuple[list[float], list[float]]:
    """``kills`` failovers with the rig armed on the checkout ``root``: (kill -> first new frame,
    kill -> rig disarmed again) in seconds."""
    workdir = Path(tempfile.mkdtemp(prefix="bench-failover-rig-"))
    rig = rig_file(workdir)
    emu, pty = emulator(rig, root)
    config = workdir / "service.toml"
    config.write_text(
        f'[tick]\nrate = 100.0\nspare_nice = 0\n[security]\ntoken = "{TOKEN}"\n[rig]\nfile = "{rig}"\nport = "{pty}"\n'
    )
    context = multiprocessing.get_context("spawn")
    proc, port = start_server(config, timeout=600.0, root=root)
    producer = context.Process(target=produce, args=(f"ws://127.0.0.1:{port}", time.perf_counter() + 7200))
    producer.start()
    frames, disarmed = [], []
    try:
        bench = Bench(port)
        bench.http.headers.update(AUTH)

        def rig_state() -> str:
            return str(bench.http.get("/api/devices").json()["devices"][0]["state"])

        for _ in range(kills):
            try:
                wait(lambda: rig_state() not in ("connecting", "parking", "unknown"), 120.0, 0.05)
                if rig_state() in ("fault", "estop"):  # a loaded host's own fault since (counted, shown)
                    print(f"{root}: the rig was {rig_state()}: reset", flush=True)
                    bench.http.post("/api/reset", json={"device": "bench3"}).raise_for_status()
                wait(lambda: rig_state() in ("disarmed", "parked"), 120.0, 0.05)
                bench.http.post("/api/arm", json={"device": "bench3"}).raise_for_status()
                wait(lambda: rig_state() == "running", 60.0, 0.05)
                s = bench.settle()
            except (RuntimeError, httpx.HTTPError) as exc:
                print(f"{root}: not armed ({exc}; rig {rig_state()}): trial skipped", flush=True)
                continue
            if rig_state() != "running":  # a failover or fault of the host's own since
                print(f"{root}: the rig stopped by itself ({rig_state()}): trial skipped", flush=True)
                continue
            at = time.perf_counter()
            os.kill(s["tick_pid"], signal.SIGKILL)
            _, arrival = bench.client.first_after(at, timeout=60.0)
            dead = s["generation"]
            wait(lambda: bench.supervision()["generation"] > dead and rig_state() == "disarmed", 60.0)  # noqa: B023
            back = time.perf_counter()
            frames.append(arrival - at)
            disarmed.append(back - at)
            print(
                f"{root}: first new frame {frames[-1] * 1e3:.0f} ms, rig disarmed {disarmed[-1] * 1e3:.0f} ms",
                flush=True,
            )
    finally:
        producer.kill()
        proc.send_signal(signal.SIGINT)
        try:
            proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
        emu.terminate()
        emu.wait(10)
    return frames, disarmed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--burners", type=int, default=0, help="busy processes at normal priority (2: both cores)")
    parser.add_argument("--kills", type=int, default=5)
    parser.add_argument("--baseline-root", type=Path, default=None, help="a checkout to compare with (main's)")
    args = parser.parse_args()
    context = multiprocessing.get_context("spawn")
    burners = [context.Process(target=burn, args=(time.perf_counter() + 7200,)) for _ in range(args.burners)]
    for burner in burners:
        burner.start()
    try:
        results = {}
        for root in ([args.baseline_root] if args.baseline_root else []) + [ROOT]:
            results[root] = run(root, args.kills)
    finally:
        for burner in burners:
            burner.kill()
    load = "loaded: both cores busy with burners" if args.burners >= 2 else f"{args.burners} burner(s)"
    print(f"bench_failover_rig: 100 Hz, bench3 armed (2 s park), {load}; load average {os.getloadavg()[0]:.1f}")
    for root, (frames, disarmed) in results.items():
        if frames:
            print(f"{root}: kill -9 -> first new frame at the client: {quantiles(frames)}")
            print(f"{root}: kill -9 -> rig disarmed under the new generation: {quantiles(disarmed)}")
    if args.baseline_root and results[args.baseline_root][0] and results[ROOT][0]:
        base = sorted(results[args.baseline_root][0])[len(results[args.baseline_root][0]) // 2]
        ours = sorted(results[ROOT][0])[len(results[ROOT][0]) // 2]
        print(f"first new frame, median: baseline / this tree = {base / ours:.1f}x")


if __name__ == "__main__":
    main()
