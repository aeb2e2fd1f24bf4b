"""A process on its way out, seen from the guardian: who holds a port, which threads still exit.

A SIGKILLed process keeps its open files, and so a port's ``flock``, until its last thread
is through the kernel's exit, which frees the whole address space (``exit_mmap``) before it
closes the files (``exit_files``). Measured on ``riderlive rig --drive`` (170 MB resident,
4 threads; docs/performance.md, "A killed driver's port"): the leader is a zombie within a
millisecond of the kill while another thread still frees memory for 40-120 ms on a quiet
host, and that thread, at normal scheduling, waits behind every busy process on a loaded
one. :func:`hasten_exit` lends the guardian's SCHED_FIFO priority to such threads; only a
process whose every thread is exiting is touched.

Linux ``/proc`` only; elsewhere every function answers "nothing found".
"""

from __future__ import annotations

import contextlib
import os
import signal


def hasten_exit(pid: int) -> int:
    """Lend this process's scheduling to the threads of ``pid``, a killed process still
    exiting; return how many threads were raised (0: none left, or this process runs at
    normal scheduling, or the host refused).

    At this process's SCHED_FIFO priority the killed process's teardown (the module
    docstring) is not starved by the host's other work, so its port is released sooner.
    Only a process whose every thread is exiting is touched (:func:`exiting_threads`): a
    live pid is left alone, and a thread already at or above this priority is not lowered.
    """
    if not hasattr(os, "sched_getscheduler") or pid <= 0:
        return 0
    try:
        policy = os.sched_getscheduler(0)
        param = os.sched_getparam(0)
    except OSError:
        return 0
    if policy != os.SCHED_FIFO:
        return 0
    raised, mine = 0, param.sched_priority
    for tid in exiting_threads(pid):
        with contextlib.suppress(OSError):  # gone meanwhile, or not permitted
            if os.sched_getscheduler(tid) == os.SCHED_FIFO and os.sched_getparam(tid).sched_priority >= mine:
                continue  # never lowered (the tick's own thread runs above this process)
            os.sched_setscheduler(tid, os.SCHED_FIFO, param)
            raised += 1
    return raised


_PF_EXITING = 0x4
"""``/proc/PID/stat`` flags: the task is in ``do_exit`` (Linux ``include/linux/sched.h``)."""
_SIGKILL_BIT = 1 << (signal.SIGKILL - 1)
"""SIGKILL in a ``/proc/PID/task/TID/status`` ``SigPnd`` mask."""


def exiting_threads(pid: int) -> list[int]:
    """The threads of ``pid`` when every one of them is exiting, else [] (a live process, or no
    /proc). Exiting: a zombie (the leader, once its own part is done), in ``do_exit``
    (``PF_EXITING``), or with SIGKILL pending (killed, not yet scheduled to run its exit: on
    a loaded host that wait is most of it)."""
    tids: list[int] = []
    try:
        for name in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{name}/stat") as f:
                fields = f.read().rsplit(")", 1)[-1].split()
            if fields[0] not in ("Z", "X") and not int(fields[6]) & _PF_EXITING and not _sigkill_pending(pid, name):
                return []
            tids.append(int(name))
    except (OSError, ValueError, IndexError):
        return []
    return tids


def _sigkill_pending(pid: int, tid: str) -> bool:
    with open(f"/proc/{pid}/task/{tid}/status") as f:
        for line in f:
            if line.startswith("SigPnd:"):
                return bool(int(line.split()[1], 16) & _SIGKILL_BIT)
    return False


def holders(port: str | None) -> str:
    """Which processes hold ``port`` open ("pid 123 (python)", ...; "" if none found or no /proc)."""
    if not port:
        return ""
    try:
        target = os.path.realpath(port)
        found = []
        for pid in filter(str.isdigit, os.listdir("/proc")):
            with contextlib.suppress(OSError):
                fds = os.listdir(f"/proc/{pid}/fd")
                if any(os.path.realpath(f"/proc/{pid}/fd/{fd}") == target for fd in fds):
                    with open(f"/proc/{pid}/comm") as comm:
                        found.append(f"pid {pid} ({comm.read().strip()})")
        return ", ".join(found)
    except OSError:
        return ""
