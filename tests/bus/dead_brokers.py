"""Brokers that are not there, for the NATS connect tests and ``bench/bench_nats_connect.py``.

A closed port (the kernel refuses), a mute one (accepts, never sends the NATS greeting),
and the real CLI raced against its own baseline: the same command with a URL nats-py
rejects before any network (port 99999: the same imports and event loop), started at the
same moment, so the difference is what the connect costs on however loaded a host.
"""

from __future__ import annotations

import contextlib
import os
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from tests.children import popen

ROOT = Path(__file__).resolve().parents[2]
BAD_URL = "nats://127.0.0.1:99999"
"""nats-py rejects this URL before any connect: the baseline of a start-up."""


def closed_port() -> int:
    """A loopback port nobody listens on (bound, then closed: the kernel refuses it)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextlib.contextmanager
def mute_port() -> Iterator[int]:
    """A loopback port that accepts connections and never writes a byte; closed on exit."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(64)
    held: list[socket.socket] = []
    stop = threading.Event()

    def accept() -> None:
        while not stop.is_set():
            try:
                conn, _ = server.accept()
            except OSError:
                return
            held.append(conn)

    threading.Thread(target=accept, daemon=True).start()
    try:
        yield int(server.getsockname()[1])
    finally:
        stop.set()
        server.close()
        for conn in held:
            conn.close()


@dataclass(frozen=True)
class Exit:
    """One CLI run: exit code, stderr, wall seconds from process start to exit."""

    code: int
    stderr: str
    wall_s: float


def race_with_baseline(command: list[str], url: str, cwd: Path) -> tuple[Exit, Exit]:
    """``riderlive COMMAND`` ({url} replaced by url) and the same with ``BAD_URL``, started at
    the same moment, each timed by its own waiter: (the run, its baseline)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), PYTHONUNBUFFERED="1")
    start = time.perf_counter()
    procs = [
        popen(
            [sys.executable, "-m", "riderlive", *(a.format(url=u) for a in command)],
            cwd=cwd,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        for u in (url, BAD_URL)
    ]
    ends, errs = [0.0, 0.0], ["", ""]

    def reap(i: int) -> None:  # neither waits for the other
        errs[i] = procs[i].communicate(timeout=300)[1]
        ends[i] = time.perf_counter() - start

    waiters = [threading.Thread(target=reap, args=(i,)) for i in range(2)]
    for w in waiters:
        w.start()
    for w in waiters:
        w.join()
    run, base = (Exit(p.returncode, e, t) for p, e, t in zip(procs, errs, ends, strict=True))
    return run, base
