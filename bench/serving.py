"""What the service benchmarks share: the real ``riderlive serve`` in a subprocess, a busy core."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[1]


def burn(stop_at: float) -> None:
    """Keep one core busy until ``stop_at`` (``perf_counter``): the other work of a shared
    machine, at normal priority (a burner spawned by a SCHED_FIFO bench would inherit
    real-time priority and compete with the very loop it is meant to stand beside)."""
    if hasattr(os, "sched_setscheduler"):
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    x = 0
    while time.perf_counter() < stop_at:
        x += 1


def start_server(config: Path, min_ticks: float = 20.0, timeout: float = 60.0) -> tuple[subprocess.Popen[str], int]:
    """``riderlive serve --config CONFIG --port 0`` in ``config``'s directory; returns once it has ticked.

    Its stderr stays a pipe (read it with ``communicate`` after stopping it).
    """
    proc = subprocess.Popen(
        [sys.executable, "-m", "riderlive", "serve", "--config", str(config), "--port", "0"],
        cwd=config.parent,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
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
