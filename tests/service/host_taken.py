"""What the host took from a live server's web process over a window of a test.

A bound on how soon the web process notices something (a dead or frozen tick) holds for the
time the host let it run: a vCPU the hypervisor took (~100 ms, several times a minute on the
shared host) or a run queue it waited on delays its look by as much, and the supervisor is
documented to excuse its own lateness (``service/stall.py``). :class:`HostTaken` measures
that time with the product's own readings (``service.stall.read_sched``,
``devices.stall.HostClock``, ``service.watch.cpu_stalls``), so such a bound is stated as
``limit + taken`` and still fails on a slow detection the host did not cause.
"""

from __future__ import annotations

import contextlib
import dataclasses
import threading
import time

from riderlive.devices.stall import HostClock
from riderlive.service.stall import read_sched
from riderlive.service.watch import CpuReading, cpu_stalls
from tests.waiting import wait_until


class HostTaken:
    """From construction to :meth:`seconds`: process ``pid``'s main thread's run-queue wait
    plus the longest any vCPU stood still or was stolen (s)."""

    def __init__(self, pid: int) -> None:
        self.pid = pid
        self._clock = HostClock()
        self._base = self._cpus()
        sched = read_sched(pid)
        self._wait = sched.wait if sched is not None else 0.0

    def _cpus(self) -> CpuReading:
        return time.perf_counter(), self._clock.cpu_seconds()

    def seconds(self) -> float:
        """The time taken so far (0 without /proc)."""
        now, sched = self._cpus(), read_sched(self.pid)
        if sched is None:
            return 0.0
        stood = [cpu_stalls(self._base, now, dataclasses.replace(sched, processor=cpu)) for cpu in range(len(now[1]))]
        vcpu = max((max(stolen, frozen) for stolen, frozen in stood), default=0.0)
        return max(0.0, sched.wait - self._wait) + vcpu


class KillTaken:
    """From construction (just before a SIGKILL of ``pid``) until the process shows it is exiting
    (``PF_EXITING``, the first thing it does with the signal) or is gone: the time the host kept
    it from acting on it, sampled every millisecond in a thread: its run-queue wait, and the time
    it slept uninterruptibly (state ``D``: a tty write the kernel's starved workers had not
    carried, say), which no signal ends. A dead tick is noticed once it exits: its notice's bound
    holds for the time it was let exit."""

    def __init__(self, pid: int) -> None:
        self.pid = pid
        self._first = read_sched(pid)
        self._last = self._first
        self.uninterruptible = 0.0
        """Seconds it was seen in state ``D`` (between two samples, counted from the first)."""
        self._seen = time.perf_counter()
        self._done = threading.Event()
        threading.Thread(target=self._watch, daemon=True).start()

    def _sample(self) -> bool:
        now, sched = time.perf_counter(), read_sched(self.pid)
        if sched is None or sched.exiting:
            return True
        if sched.state == "D":
            self.uninterruptible += now - self._seen
        self._seen, self._last = now, sched
        return False

    def _watch(self) -> None:
        with contextlib.suppress(AssertionError):
            wait_until(self._sample, 10.0, "the killed process never exited", poll=0.001)
        self._done.set()

    def seconds(self) -> float:
        """The time taken (waits for the process to exit, up to 10 s)."""
        self._done.wait(11.0)
        if self._first is None or self._last is None:
            return 0.0
        return max(0.0, self._last.wait - self._first.wait) + self.uninterruptible
