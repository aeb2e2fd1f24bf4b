"""devices/exiting: which threads of a process are exiting, and lending them the guardian's priority.

Only a process whose every thread is on its way out may be raised: a live one (a tick that
merely looks slow, a pid reused by an unrelated process) must keep its scheduling.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import threading
from collections.abc import Iterator

import pytest

from riderlive.devices.exiting import exiting_threads, hasten_exit, holders

THREADS = "import threading, time\nfor _ in range(3): threading.Thread(target=time.sleep, args=(60,)).start()\n"
THREADS += "print('ready', flush=True)\ntime.sleep(60)\n"


@pytest.fixture
def victim() -> Iterator[subprocess.Popen[str]]:
    """A live python process with four threads (it says ``ready`` once they run)."""
    proc = subprocess.Popen([sys.executable, "-c", THREADS], stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None and proc.stdout.readline() == "ready\n"
    yield proc
    proc.kill()
    proc.wait()


def policy(pid: int) -> list[tuple[int, int]]:
    tids = [int(t) for t in os.listdir(f"/proc/{pid}/task")]
    return [(os.sched_getscheduler(t), os.sched_getparam(t).sched_priority) for t in tids]


def test_a_live_process_has_no_exiting_threads_and_is_never_raised(victim: subprocess.Popen[str]) -> None:
    assert len(os.listdir(f"/proc/{victim.pid}/task")) == 4
    assert exiting_threads(victim.pid) == []
    assert exiting_threads(os.getpid()) == []
    before = policy(victim.pid)
    raised: list[int] = []

    def at_fifo() -> None:  # the guardian's case: this thread at SCHED_FIFO
        with contextlib.suppress(PermissionError):  # at normal scheduling it raises nobody either
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
        raised.append(hasten_exit(victim.pid))

    thread = threading.Thread(target=at_fifo)
    thread.start()
    thread.join()
    assert raised == [0]
    assert policy(victim.pid) == before


def test_a_killed_process_is_all_exiting_until_reaped(victim: subprocess.Popen[str]) -> None:
    victim.kill()
    # Until reaped, its leader stays a zombie: wait for its exit without reaping it.
    os.waitid(os.P_PID, victim.pid, os.WEXITED | os.WNOWAIT)
    assert exiting_threads(victim.pid) == [victim.pid]
    victim.wait()
    assert exiting_threads(victim.pid) == []
    assert hasten_exit(victim.pid) == 0
    assert hasten_exit(0) == 0 and hasten_exit(-1) == 0


def test_holders_names_the_processes_that_hold_a_file(tmp_path: object) -> None:
    path = os.path.join(str(tmp_path), "port")
    with open(path, "w"):
        assert f"pid {os.getpid()} " in holders(path)
    assert holders(None) == ""
