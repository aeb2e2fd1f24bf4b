"""Where a late servo reply's time goes on a busy host: which clock explains it.

    PYTHONPATH=$PWD .venv/bin/python bench/probe_stall.py [--seconds 20] [--modes nice0 nice10 pinned quiet]

A SCHED_FIFO 50 requester (as the tick) writes 20 bytes to a pty at 120 Hz and waits in
``select`` for a SCHED_FIFO 60 peer (as the emulated servo) to echo them; two burners
load the cores at normal priority (``nice0``), at nice 10 (``nice10``), pinned to the
last CPU while the requester and the peer are pinned to CPU 0 (``pinned``: CPU
isolation), or none (``quiet``). For every transaction it reads the requester's own
run-queue wait (``/proc/thread-self/schedstat`` field 2), the peer's, and the steal time
of every CPU (``/proc/stat``); the rest of a reply's time is the serial path (the
kernel's normal-priority tty worker that carries the bytes) and the wire-free pty.

Prints, per mode: round-trip p50/p99/max, the transactions over 5 ms and what explains
each (steal >= half of it; the peer's run-queue wait; the requester's own; else the
serial path), and the worst transactions with their parts.
"""

from __future__ import annotations

import argparse
import contextlib
import multiprocessing as mp
import os
import pty
import select
import time
import tty

from riderlive.devices.stall import HostClock
from riderlive.service.kworkers import census

MODES = ("quiet", "nice0", "nice10", "pinned")


def burn(stop_at: float, nice: int, cpu: int | None) -> None:
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    os.nice(nice)
    if cpu is not None:
        os.sched_setaffinity(0, {cpu})
    while time.time() < stop_at:
        pass


def echo(fd: int, cpu: int | None) -> None:
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(60))
    if cpu is not None:
        os.sched_setaffinity(0, {cpu})
    while True:
        data = os.read(fd, 64)
        if not data:
            return
        os.write(fd, data)


def schedstat(path: str) -> tuple[int, int]:
    with open(path) as f:
        run, wait = f.read().split()[:2]
    return int(run), int(wait)


def probe(mode: str, seconds: float) -> dict[str, float]:
    cpus = sorted(os.sched_getaffinity(0))
    pinned = mode == "pinned" and len(cpus) > 1
    master, slave = pty.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    peer = mp.get_context("fork").Process(target=echo, args=(slave, cpus[0] if pinned else None), daemon=True)
    peer.start()
    stop_at = time.time() + seconds
    burners = []
    if mode != "quiet":
        nice = 10 if mode == "nice10" else 0
        for _ in range(2):
            args = (stop_at, nice, cpus[-1] if pinned else None)
            burners.append(mp.get_context("fork").Process(target=burn, args=args, daemon=True))
    for b in burners:
        b.start()
    old = os.sched_getaffinity(0)
    if pinned:
        os.sched_setaffinity(0, {cpus[0]})
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(50))
    host = HostClock()
    me, other = "/proc/thread-self/schedstat", f"/proc/{peer.pid}/schedstat"
    rows = []
    period = 1 / 120
    next_at = time.perf_counter()
    try:
        while time.time() < stop_at:
            next_at += period
            delay = next_at - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            (e0, w0), (_, p0), s0 = schedstat(me), schedstat(other), host.steal_s()
            t0 = time.perf_counter()
            os.write(master, b"x" * 20)
            got = 0
            while got < 20 and select.select([master], [], [], 1.0)[0]:
                got += len(os.read(master, 64))
            t1 = time.perf_counter()
            (e1, w1), (_, p1), s1 = schedstat(me), schedstat(other), host.steal_s()
            steal = max((b - a for a, b in zip(s0, s1, strict=True)), default=0.0)
            rows.append((t1 - t0, (w1 - w0) / 1e9, (e1 - e0) / 1e9, (p1 - p0) / 1e9, steal))
    finally:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        os.sched_setaffinity(0, old)
        for b in burners:
            b.join()
        os.close(master)
        peer.kill()
        peer.join()
        with contextlib.suppress(OSError):
            os.close(slave)
    rtts = sorted(r[0] for r in rows)
    n = len(rtts)
    late = [r for r in rows if r[0] > 0.005]
    kinds = {"steal": 0, "peer": 0, "own": 0, "serial path": 0}
    for rtt, own, _, peer_wait, steal in late:
        if steal >= rtt / 2:
            kinds["steal"] += 1
        elif peer_wait >= rtt / 2:
            kinds["peer"] += 1
        elif own >= rtt / 2:
            kinds["own"] += 1
        else:
            kinds["serial path"] += 1
    print(
        f"{mode:7s} {n} transactions: p50 {rtts[n // 2] * 1e3:.3f} ms, p99 {rtts[int(n * 0.99)] * 1e3:.3f} ms, "
        f"max {rtts[-1] * 1e3:.1f} ms; over 5 ms: {len(late)} ({', '.join(f'{k} {v}' for k, v in kinds.items())})"
    )
    for rtt, own, run, peer_wait, steal in sorted(rows, reverse=True)[:4]:
        print(
            f"        {rtt * 1e3:6.2f} ms: own run-queue wait {own * 1e3:.2f}, own cpu {run * 1e3:.2f}, "
            f"peer run-queue wait {peer_wait * 1e3:.2f}, steal (largest CPU) {steal * 1e3:.0f}, "
            f"rest (serial path) {(rtt - own - run - peer_wait) * 1e3:.2f}"
        )
    return {"p99_ms": rtts[int(n * 0.99)] * 1e3, "max_ms": rtts[-1] * 1e3, "late": len(late)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--modes", nargs="+", choices=MODES, default=list(MODES))
    args = parser.parse_args()
    print(f"{os.cpu_count()} CPUs; the requester at SCHED_FIFO 50, the echo at 60, 120 transactions/s of 20 bytes")
    print(f"unbound kernel workers (the pty's serial path): {dict(census())} (raise them: riderlive host tune)")
    for mode in args.modes:
        probe(mode, args.seconds)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
