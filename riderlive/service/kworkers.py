"""The kernel's unbound workers raised to a low SCHED_FIFO priority (``[host] kernel_workers_priority``).

A servo's reply reaches the tick through the kernel's tty flip buffer: the driver (a USB
adapter's completion, or a pty's writer) queues ``flush_to_ldisc`` on the unbound
workqueue (``drivers/tty/tty_buffer.c``), and a ``kworker/uN:M`` thread at normal
priority runs it. With both cores busy that thread waits for the CPU like any other
process: measured up to 4.0 ms per transfer on a pty at 500 Hz (bench/bench_estop.py) and
the soak's faults and false hangs (docs/performance.md "Kernel workers"). The kernel has
no per-tty knob for this here (``low_latency`` stopped bypassing the worker in 3.15; a
per-driver sysfs workqueue with ``nice`` and ``cpumask`` is newer than 6.18), so the
workers themselves are raised, below every riderlive thread (the web process's 10).

:func:`wanted` is the pure policy (which threads, to what); :class:`KernelWorkers` is the
edge: it lists kthreadd's children (``/proc/2/task/2/children``; every ``/proc`` pid when
the kernel lacks that file), reads each new pid's name once, and asks the scheduler
(``os.sched_setscheduler``). New workers appear as the kernel needs them, so the web
process scans again every ``RESCAN_S`` (``Service``; a tick's death does not stop it). Not
the guardian: the dead-man stays as small as it can be, and the workers matter only while
the service drives devices (with the web process gone the guardian parks them).
Raised workers go back to normal scheduling when the service stops; a killed web process
leaves them raised until the next start or reboot (RT throttling,
``/proc/sys/kernel/sched_rt_runtime_us``, still leaves 5 % of each CPU to normal work).
"""

from __future__ import annotations

import asyncio
import enum
import errno
import logging
import os
import re
import time
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from riderlive.prometheus import Exposition, Kind

log = logging.getLogger(__name__)

UNBOUND_WORKER = re.compile(r"kworker/u\d+:\d+")
"""The name of an unbound workqueue worker (``kworker/u8:2``; ``/proc`` may add ``-events_unbound``)."""
MAX_PRIORITY = 9
"""Highest allowed priority: below the web process's SCHED_FIFO 10 (riderlive/sched.py)."""
RESCAN_S = 1.0
"""Seconds between scans for new workers (the kernel makes new ones as work piles up)."""
KTHREADD = 2
RESET_ON_FORK = 0x40000000
"""``SCHED_RESET_ON_FORK``, a flag ``sched_getscheduler`` may add to the policy."""
PROC = Path("/proc")


class Sched(enum.IntEnum):
    """Linux scheduling policies (``sched.h``), as ``os.sched_getscheduler`` returns them."""

    OTHER = 0
    FIFO = 1
    RR = 2
    BATCH = 3
    IDLE = 5
    DEADLINE = 6


@dataclass(frozen=True)
class KThread:
    """One thread as the scheduler sees it."""

    pid: int
    comm: str
    policy: int
    """``Sched`` value (an unknown policy is kept as its number)."""
    priority: int
    """SCHED_FIFO/RR priority, 0 for the other policies."""


def is_unbound_worker(comm: str) -> bool:
    """``comm`` names an unbound workqueue worker (``kworker/u8:2``), not a per-CPU one
    (``kworker/0:1``), a rescuer (``kworker/R-...``) or another thread."""
    return UNBOUND_WORKER.match(comm) is not None


def wanted(thread: KThread, priority: int, match: Callable[[str], bool] = is_unbound_worker) -> bool:
    """``thread`` must be raised to SCHED_FIFO ``priority``: it matches, and runs at normal
    scheduling (OTHER, BATCH, IDLE) or at SCHED_FIFO/RR below ``priority``. One raised higher
    by someone else, and SCHED_DEADLINE, are left alone; ``priority`` 0 raises nothing."""
    if priority <= 0 or not match(thread.comm):
        return False
    if thread.policy in (Sched.FIFO, Sched.RR):
        return thread.priority < priority
    return thread.policy in (Sched.OTHER, Sched.BATCH, Sched.IDLE)


def check_priority(priority: int) -> int:
    """``priority`` if allowed (0: off, 1..MAX_PRIORITY), else ValueError naming the range."""
    if not 0 <= priority <= MAX_PRIORITY:
        raise ValueError(f"must be 0 (off) or 1..{MAX_PRIORITY} (SCHED_FIFO below the web process's 10)")
    return priority


@dataclass
class WorkerStats:
    """What the scans did, for ``/api/state`` (``host.kernel_workers``) and ``/metrics``."""

    priority: int
    scans: int = 0
    raised: int = 0
    """Successful raises since start (a worker counts once per raise)."""
    failures: Counter[str] = field(default_factory=Counter)
    """Failed raises by errno name (EPERM: not root / no CAP_SYS_NICE)."""
    workers: int = 0
    """Matching workers seen by the last scan."""
    below: int = 0
    """Of them, still below ``priority`` after the last scan (0 when all is well)."""
    scan_cpu_s: float = 0.0
    """CPU time of all scans (this thread's), seconds."""
    last_error: str = ""

    def status(self) -> dict[str, Any]:
        return {
            "priority": self.priority,
            "scans": self.scans,
            "workers": self.workers,
            "below_priority": self.below,
            "raised": self.raised,
            "failures": dict(self.failures),
            "scan_cpu_ms_mean": round(1e3 * self.scan_cpu_s / self.scans, 4) if self.scans else 0.0,
            "last_error": self.last_error,
        }

    def prometheus(self) -> str:
        """Prometheus text of these counts."""
        out = Exposition()
        out.one(
            "riderlive_kernel_workers_priority",
            Kind.GAUGE,
            "SCHED_FIFO priority asked for the kernel's unbound workers.",
            self.priority,
        )
        states = (("raised", self.workers - self.below), ("below", self.below))
        out.by_label(
            "riderlive_kernel_workers",
            Kind.GAUGE,
            "Unbound kernel workers seen by the last scan, by state.",
            "state",
            states,
        )
        out.one(
            "riderlive_kernel_workers_raised_total",
            Kind.COUNTER,
            "Unbound kernel workers raised to the priority.",
            self.raised,
        )
        failures = sorted(self.failures.items())
        out.by_label(
            "riderlive_kernel_workers_failures_total", Kind.COUNTER, "Failed raises, by errno.", "errno", failures
        )
        return out.text()


def kthreadd_children(proc: Path = PROC) -> list[int]:
    """The kernel threads' pids (kthreadd's children); every ``/proc`` pid when the kernel
    does not list children (CONFIG_PROC_CHILDREN off)."""
    try:
        return [int(p) for p in (proc / f"{KTHREADD}/task/{KTHREADD}/children").read_text().split()]
    except OSError:
        return all_pids(proc)


def all_pids(proc: Path = PROC) -> list[int]:
    """Every process id in ``/proc``."""
    return [int(name) for name in os.listdir(proc) if name.isdigit()]


def read_sched(pid: int, comm: str) -> KThread:
    """``pid``'s policy and priority now (OSError: gone, or not ours to see)."""
    policy = os.sched_getscheduler(pid) & ~RESET_ON_FORK
    priority = os.sched_getparam(pid).sched_priority if policy in (Sched.FIFO, Sched.RR) else 0
    return KThread(pid, comm, policy, priority)


class KernelWorkers:
    """Raises the matching threads to SCHED_FIFO ``priority`` on each :meth:`scan`."""

    def __init__(
        self,
        priority: int,
        pids: Callable[[], Iterable[int]] = kthreadd_children,
        match: Callable[[str], bool] = is_unbound_worker,
        proc: Path = PROC,
    ) -> None:
        self.stats = WorkerStats(check_priority(priority))
        self._pids, self._match, self._proc = pids, match, proc
        self._names: dict[int, str] = {}
        """Each pid seen, with its name then (kernel threads keep their ``kworker/uN:M`` part; a pid
        that exits and is reused by another kernel thread within one scan keeps the old name:
        pids are handed out in order up to ``pid_max`` before any is reused)."""
        self._mine: set[int] = set()
        """Pids this instance raised (restored by :meth:`restore`)."""

    def _name(self, pid: int) -> str:
        name = self._names.get(pid)
        if name is None:
            try:
                name = (self._proc / f"{pid}/comm").read_text().strip()
            except OSError:
                name = ""
            self._names[pid] = name
        return name

    def scan(self) -> WorkerStats:
        """One pass: every matching thread below the priority raised (failures counted)."""
        started = time.thread_time()
        stats, priority = self.stats, self.stats.priority
        pids = set(self._pids())
        for gone in self._names.keys() - pids:
            del self._names[gone]
            self._mine.discard(gone)
        workers = below = 0
        for pid in pids:
            comm = self._name(pid)
            if not self._match(comm):
                continue
            try:
                thread = read_sched(pid, comm)
            except OSError:
                continue  # gone between the listing and now
            workers += 1
            if not wanted(thread, priority, self._match):
                continue
            try:
                os.sched_setscheduler(pid, Sched.FIFO, os.sched_param(priority))
            except OSError as exc:
                if exc.errno == errno.ESRCH:
                    workers -= 1
                    continue
                below += 1
                stats.failures[errno.errorcode.get(exc.errno or 0, "unknown")] += 1
                stats.last_error = f"{comm} ({pid}): {exc.strerror}"
                continue
            stats.raised += 1
            self._mine.add(pid)
        stats.scans += 1
        stats.workers, stats.below = workers, below
        stats.scan_cpu_s += time.thread_time() - started
        return stats

    def restore(self) -> int:
        """Put the threads this instance raised (and still at its priority) back to normal
        scheduling; returns how many."""
        done = 0
        for pid in sorted(self._mine):
            try:
                thread = read_sched(pid, self._names.get(pid, ""))
                if thread.policy == Sched.FIFO and thread.priority == self.stats.priority:
                    os.sched_setscheduler(pid, Sched.OTHER, os.sched_param(0))
                    done += 1
            except OSError:
                continue
        self._mine.clear()
        return done


def census(proc: Path = PROC) -> Counter[str]:
    """The unbound kernel workers now, by scheduling (``"normal"``, ``"FIFO 1"``, ...): what a
    bench prints with its figures, what ``hostcheck`` warns about."""
    out: Counter[str] = Counter()
    for pid in kthreadd_children(proc):
        try:
            comm = (proc / f"{pid}/comm").read_text().strip()
            if is_unbound_worker(comm):
                thread = read_sched(pid, comm)
                rt = thread.policy in (Sched.FIFO, Sched.RR)
                out[f"{Sched(thread.policy).name} {thread.priority}" if rt else "normal"] += 1
        except OSError:
            continue
    return out


def normal_workers(proc: Path = PROC) -> int:
    """How many unbound kernel workers run at normal scheduling now (``hostcheck``)."""
    return census(proc)["normal"]


async def keep_raised(workers: KernelWorkers, interval_s: float = RESCAN_S) -> None:
    """Scan every ``interval_s`` on the web process's event loop (a scan of known workers
    costs ~0.1-0.3 ms of CPU; a thread would hold the GIL at normal priority against the
    loop's SCHED_FIFO 10) until cancelled; then restore the raised workers."""
    warned = False
    try:
        while True:
            try:
                stats = workers.scan()
            except Exception as exc:  # a scan must never end the service: counted, shown, retried
                workers.stats.failures[type(exc).__name__] += 1
                workers.stats.last_error = repr(exc)
                log.exception("kernel workers: scan failed")
            else:
                if stats.below and not warned:
                    warned = True
                    log.warning(
                        "kernel workers: %d unbound workers stay below SCHED_FIFO %d (%s); "
                        "host.kernel_workers_priority needs root (CAP_SYS_NICE)",
                        stats.below,
                        stats.priority,
                        stats.last_error,
                    )
            await asyncio.sleep(interval_s)
    finally:
        workers.restore()


def host_status(workers: KernelWorkers | None) -> dict[str, Any]:
    """``/api/state``'s ``host`` section."""
    return {"kernel_workers": None if workers is None else workers.stats.status()}
