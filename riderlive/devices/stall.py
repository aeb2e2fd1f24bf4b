"""Host stalls: the part of a unit's silence that a budget must not charge to the unit.

A reply that came late because this host was not running is not the servo's fault.
What counts as "not running", measured on a 2-vCPU guest with both cores loaded by
normal-priority burners (``bench/probe_stall.py``; docs/hardware.md, "A busy host"):

- the requesting thread's own run-queue wait (``/proc/thread-self/schedstat`` field 2)
  explains none of the long gaps: the tick waits for a reply asleep in ``select``, so
  its run queue wait stays ~0 while the reply is late;
- the host's **steal time** (``/proc/stat``, per CPU, in clock ticks) explains every
  gap over 20 ms: a 98.6 ms reply came with 98.3 ms of run-queue wait of the replying
  process (at SCHED_FIFO 60) and 100 ms of steal: the hypervisor had taken the vCPU,
  so nothing in the guest ran, whatever its priority.

So the time lost between two samples is this thread's run-queue wait (a real-time tick
preempted by a higher-priority thread, bare metal) plus the largest steal any one CPU
saw (a vCPU taken away), never more than the wall time between them. A real silence
(a servo that vanished) on a host that runs is charged in full: the budget is
``reply_budget_s`` of *usable* time, so a stall of S seconds delays that detection by
at most S.

:class:`HostSample` and :func:`silence_step` are pure (state in, state out);
:class:`HostClock` reads the kernel's counters (the only I/O here). Times in seconds.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

PROC_STAT = Path("/proc/stat")
RESOLUTION_S = 1e-9
"""Two times this close are equal (the kernel's counters are in ns): a budget is reached
at exactly its length, not one rounding error later."""


@dataclass(frozen=True)
class HostSample:
    """One reading: ``wall_s`` (the caller's monotonic clock), this thread's cumulative
    run-queue wait ``waited_s`` and each CPU's cumulative steal ``stolen_s``."""

    wall_s: float
    waited_s: float = 0.0
    stolen_s: tuple[float, ...] = ()


def lost_between(a: HostSample, b: HostSample) -> float:
    """Seconds of ``(a, b]`` the host could not run us: own run-queue wait plus the largest
    one-CPU steal, clamped to ``[0, wall time]``."""
    wall = max(0.0, b.wall_s - a.wall_s)
    stolen = max((max(0.0, y - x) for x, y in zip(a.stolen_s, b.stolen_s, strict=False)), default=0.0)
    return min(wall, max(0.0, b.waited_s - a.waited_s) + stolen)


def usable_between(a: HostSample, b: HostSample) -> float:
    """Wall seconds of ``(a, b]`` minus :func:`lost_between`: the time the unit had."""
    return max(0.0, b.wall_s - a.wall_s) - lost_between(a, b)


@dataclass(frozen=True)
class Silence:
    """A unit over its budget: its index, silent ``usable_s`` (charged) and ``lost_s``
    (the host's stalls in the same span, not charged)."""

    index: int
    usable_s: float
    lost_s: float


@dataclass(frozen=True)
class SilenceState:
    """When each unit was last heard from before its current silence (None: not silent)."""

    since: tuple[HostSample | None, ...]

    @classmethod
    def fresh(cls, units: int) -> SilenceState:
        return cls((None,) * units)

    @property
    def silent(self) -> bool:
        return any(s is not None for s in self.since)


def silence_step(
    state: SilenceState, asked: Sequence[bool], heard: Sequence[bool], now: HostSample | None, budget_s: float
) -> tuple[SilenceState, list[Silence]]:
    """One read's outcome: a unit heard is no longer silent; a unit asked and not heard is
    silent since ``now`` if it was not already. Returns the new state and every unit whose
    usable silence reached ``budget_s`` (longest first). ``now`` may be None only when
    every asked unit was heard (the caller need not read the host's counters then)."""
    since = list(state.since)
    over: list[Silence] = []
    for i, (was_asked, was_heard) in enumerate(zip(asked, heard, strict=True)):
        if was_heard:
            since[i] = None
            continue
        if not was_asked:
            continue
        if now is None:
            raise ValueError("a unit was asked and not heard: a HostSample is needed")
        start = since[i]
        if start is None:
            since[i] = now
            continue
        usable = usable_between(start, now)
        if usable >= budget_s - RESOLUTION_S:
            over.append(Silence(i, usable, lost_between(start, now)))
    over.sort(key=lambda s: -s.usable_s)
    return SilenceState(tuple(since)), over


class Sampler(Protocol):
    def sample(self, wall_s: float) -> HostSample: ...


class HostClock:
    """Reads the calling thread's run-queue wait and the CPUs' steal (Linux; elsewhere
    both stay 0, and budgets are plain wall time). Costs ~50 us a sample: the readback
    samples only while a unit is silent."""

    def __init__(self, stat: Path = PROC_STAT) -> None:
        self.stat = stat
        self.tick_s = 1.0 / os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 0.01

    def sample(self, wall_s: float) -> HostSample:
        return HostSample(wall_s, thread_run_delay_s(), self.steal_s())

    def steal_s(self) -> tuple[float, ...]:
        """Each CPU's cumulative steal time (the 8th value of its ``cpuN`` line)."""
        return tuple(steal for _, steal in self.cpu_seconds())

    def cpu_seconds(self) -> tuple[tuple[float, float], ...]:
        """Each CPU's cumulative (accounted, steal) seconds (:func:`parse_cpu_seconds`; () without /proc)."""
        try:
            text = self.stat.read_text()
        except OSError:
            return ()
        return parse_cpu_seconds(text, self.tick_s)


def parse_steal(text: str, tick_s: float) -> tuple[float, ...]:
    """Steal seconds of each ``cpuN`` line of a ``/proc/stat`` text (not the ``cpu`` total)."""
    return tuple(steal for _, steal in parse_cpu_seconds(text, tick_s))


ACCOUNTED_FIELDS = 7
"""The ``cpuN`` fields of ``/proc/stat`` summed as a CPU's accounted time (user, nice,
system, idle, iowait, irq, softirq)."""


def accounting_error_s(tick_s: float) -> float:
    """The most a CPU's accounted time (:func:`parse_cpu_seconds`) between two readings may
    differ from the wall time between them with its vCPU never taken (s): each of the
    :data:`ACCOUNTED_FIELDS` is shown in ``tick_s`` units (USER_HZ), rounded down on its own,
    so each may hide under one unit; and a busy CPU accounts at its scheduler ticks, so one
    reading may lag the other by a kernel tick (no longer than a USER_HZ unit: HZ >= 100).
    Seen: 1 unit on this machine (quiet, and beside two busy loops), 3 in CI."""
    return (ACCOUNTED_FIELDS + 1) * tick_s


def parse_cpu_seconds(text: str, tick_s: float) -> tuple[tuple[float, float], ...]:
    """Each ``cpuN`` line's (accounted, steal) seconds: ``accounted`` is the guest's own time
    (user, nice, system, idle, iowait, irq, softirq). A busy CPU accounts its time at each
    scheduler tick and an idle one at each read, so ``accounted`` follows the wall clock,
    except on a vCPU the hypervisor took: nothing there runs, not even its tick, so its
    ``accounted`` stands still, and its steal is added only once it runs again."""
    out = []
    for line in text.splitlines():
        if not line.startswith("cpu"):
            break
        fields = line.split()
        if fields[0] == "cpu" or len(fields) < 9:
            continue
        accounted = sum(int(f) for f in fields[1 : 1 + ACCOUNTED_FIELDS])
        out.append((accounted * tick_s, int(fields[1 + ACCOUNTED_FIELDS]) * tick_s))
    return tuple(out)


def thread_run_delay_s() -> float:
    """The calling thread's cumulative run-queue wait (s; 0 where not available)."""
    try:
        with open(f"/proc/self/task/{threading.get_native_id()}/schedstat", "rb") as f:
            return int(f.read().split()[1]) / 1e9
    except (OSError, ValueError, IndexError):
        return 0.0
