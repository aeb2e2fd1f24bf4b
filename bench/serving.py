"""What the service benchmarks share: the real ``riderlive serve`` in a subprocess, a busy core."""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import re
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[1]


def burn(stop_at: float) -> None:
    """Keep one core busy until ``stop_at`` (``perf_counter``): the other work of a shared
    machine, at normal priority (a burner spawned by a SCHED_FIFO bench would inherit
    real-time priority and compete with the very loop it is meant to stand beside)."""
    if hasattr(os, "sched_setscheduler"):
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    if hasattr(os, "sched_setaffinity"):  # nor the bench's pinning: other work runs where it likes
        os.sched_setaffinity(0, range(os.cpu_count() or 1))
    x = 0
    while time.perf_counter() < stop_at:
        x += 1


@contextlib.contextmanager
def busy_cores(count: int, seconds: float = 7200.0) -> Iterator[str]:
    """``count`` burners (``burn``) beside the body, for at most ``seconds``; yields the words
    every figure printed inside should carry ("quiet" or "loaded (N busy processes)").

    Spawned, not forked, so a burner never inherits the bench's SCHED_FIFO or its threads;
    stopped and joined on the way out, whatever the body raised."""
    context = mp.get_context("spawn")
    procs = [context.Process(target=burn, args=(time.perf_counter() + seconds,), daemon=True) for _ in range(count)]
    for proc in procs:
        proc.start()
    try:
        plural = "es" if count > 1 else ""
        yield f"loaded ({count} busy process{plural})" if count else "quiet (other users' load not controlled)"
    finally:
        for proc in procs:
            proc.terminate()
        for proc in procs:
            proc.join()


def start_server(
    config: Path, min_ticks: float = 20.0, timeout: float = 60.0, root: Path = ROOT
) -> tuple[subprocess.Popen[str], int]:
    """``riderlive serve --config CONFIG --port 0`` of the checkout ``root`` (a baseline: main's)
    in ``config``'s directory; returns once it has ticked.

    Its stderr stays a pipe (read it with ``communicate`` after stopping it).
    """
    proc = subprocess.Popen(
        [sys.executable, "-m", "riderlive", "serve", "--config", str(config), "--port", "0"],
        cwd=config.parent,
        env=dict(os.environ, PYTHONPATH=str(root)),
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stderr is not None
    port = 0
    for line in proc.stderr:
        match = re.search(r"listening on port (\d+)", line)
        if match:
            port = int(match.group(1))
            break
    deadline = time.perf_counter() + timeout
    while time.perf_counter() < deadline:
        try:
            if httpx.get(f"http://127.0.0.1:{port}/api/state", timeout=2).json()["counters"]["ticks"] > min_ticks:
                return proc, port
        except (httpx.HTTPError, KeyError, ValueError):
            pass
        time.sleep(0.1)
    proc.kill()
    raise RuntimeError("the server did not start")
