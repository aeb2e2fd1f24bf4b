"""Processes a test run starts die with it, however it ends.

A killed pytest (SIGTERM, a CI timeout, SIGKILL) used to leave its ``riderlive serve``
processes running, each relaunching its guardian (two such orphans ran for an hour).
Three layers, each enough for the case it covers:

- :func:`with_parent_death`: the command run through ``setpriv --pdeathsig TERM``, so the
  kernel sends it SIGTERM when the thread that started it dies; ``riderlive serve`` then
  shuts down as on Ctrl-C (parks, stops its tick and its guardians). Covers SIGKILL of
  pytest, where no Python code of pytest runs.
- :data:`MARKER`: every process this run starts, and their children (the tick process, the
  guardians, brokers), inherit ``RIDERLIVE_TEST_RUN=<pytest's pid>`` in their environment;
  :func:`sweep` ends every live process carrying it (SIGTERM, then SIGKILL after a grace).
- ``tests/conftest.py`` turns SIGTERM into KeyboardInterrupt (fixtures' finalizers stop
  their servers) and sweeps at the end of the session and at exit.

Linux only (the suite's platform): ``setpriv`` (util-linux) and ``/proc``.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

from tests.waiting import wait_until

MARKER = "RIDERLIVE_TEST_RUN"
"""The environment variable naming the pytest process whose run started a process."""
SETPRIV = "/usr/bin/setpriv"
"""util-linux's (Debian's essential set): sets the parent-death signal, then execs."""


def mark_run() -> str:
    """Set :data:`MARKER` to this run in ``os.environ`` and return it: this process's pid (a
    pytest started by a test is a run of its own), or for an xdist worker its controller's
    run, a ``/`` and its own pid: each worker sweeps its own children, and the controller's
    sweep also ends those of a worker that was killed before its own sweep ran (a
    nats-server from ``riderlive/bus/broker.py`` outlived a killed worker)."""
    inherited = os.environ.get(MARKER)
    worker = os.environ.get("PYTEST_XDIST_WORKER") and inherited
    os.environ[MARKER] = f"{inherited}/{os.getpid()}" if worker else str(os.getpid())
    return os.environ[MARKER]


def with_parent_death(command: Sequence[str], sig: signal.Signals = signal.SIGTERM) -> list[str]:
    """``command`` run through util-linux ``setpriv --pdeathsig``: it execs the command in
    the same process (same pid) after ``prctl(PR_SET_PDEATHSIG, sig)``, so the command gets
    ``sig`` when the thread that started it ends (:func:`popen` starts it from a thread that
    lives as long as the run). An exec wrapper, not a ``preexec_fn``:
    Python code between fork and exec is unsafe with threads (Playwright's, readers')."""
    return [SETPRIV, "--pdeathsig", sig.name.removeprefix("SIG"), "--", *command]


_SPAWNER = ThreadPoolExecutor(max_workers=1, thread_name_prefix="children-spawner")
"""One thread that lives as long as the test run starts every child: the parent-death
signal follows the *thread* that forked, and a fixture that starts its servers from
short-lived threads (tests/bus/test_stage_safety.py) would have them SIGTERMed the
moment those threads ended."""


def popen(command: Sequence[str], **kwargs: Any) -> subprocess.Popen[Any]:
    """``subprocess.Popen(with_parent_death(command), **kwargs)``, forked from the run's one
    long-lived spawner thread (from any thread of the test run)."""
    return _SPAWNER.submit(subprocess.Popen, with_parent_death(command), **kwargs).result()


def marked(run: str) -> list[int]:
    """Pids of live processes (not zombies, not this one) whose environment has ``MARKER=run``
    or a worker's run of it (``MARKER=run/pid``)."""
    wanted = f"{MARKER}={run}".encode()
    worker = wanted + b"/"
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        with contextlib.suppress(OSError):
            if not any(v == wanted or v.startswith(worker) for v in (entry / "environ").read_bytes().split(b"\0")):
                continue
            if (entry / "stat").read_text().rsplit(")", 1)[1].split()[0] == "Z":
                continue
            found.append(int(entry.name))
    return found


def sweep(run: str, grace_s: float = 5.0) -> list[int]:
    """End every process of ``run`` still alive: SIGTERM (a server parks and stops its
    children), then SIGKILL what is left after ``grace_s``. Returns the pids it signalled."""
    first = marked(run)
    for pid in first:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.kill(pid, signal.SIGTERM)
    if first:
        with contextlib.suppress(AssertionError):  # what is left after the grace is killed below
            wait_until(lambda: not marked(run), grace_s, poll=0.1)  # not our children: no event to await
    for pid in marked(run):
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.kill(pid, signal.SIGKILL)
    return first
