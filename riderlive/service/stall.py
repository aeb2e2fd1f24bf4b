"""Is the tick hung, or did the host stall everyone? A pure classification, plus its /proc edge.

The supervisor (``service/supervisor.py``) checks the tick's heartbeat every half period.
A heartbeat older than the hang threshold used to be a hang, yet on a busy 2-core host a
normal-priority process is not run for tens of milliseconds now and then, and the
supervisor itself wakes late by as much: the tick was not stuck, the host was. Killing it
then cost a restart for nothing (and, before the warm spare, seconds without a frame).

:func:`classify` takes one :class:`Observation` (times in seconds, any common clock) and
the :class:`Model`'s thresholds and returns a :class:`Verdict`:

- **discounts**: the tick's heartbeat age is discounted by the time it could not have
  beaten for reasons outside it, the largest of (they overlap in time, so they are not
  added): the supervisor's own wake-up lateness (it saw the age late), the tick's
  run-queue wait since its last beat (``/proc/<pid>/schedstat``: runnable but not run),
  the stall of another process's heartbeat (the guardian's on the safety board) over the
  same time, and the largest one-CPU steal time (a 2-vCPU guest's hypervisor takes a
  whole vCPU for ~100 ms: ``riderlive.devices.stall``, whose reading is used). What is
  left is measured against the threshold.
- **stopped** (``T`` in ``/proc/<pid>/stat``, a SIGSTOP): nothing excuses it but the
  supervisor's own lateness.
- **starved** for longer than ``Model.longest_excuse``: hung after all (killing it will
  not help much, but a tick nobody runs for that long is out of service).
- **dying** (``PF_EXITING``): a kill the sentinel will tell only once the process's memory
  is released: failed over at once.
- **starting** (no heartbeat yet): never killed while it makes progress (CPU time or
  run-queue wait grew in the last ``Model.start_stuck`` seconds); killed only when it
  made none for that long, or took ``Model.start_limit`` in all.

No clock is read here: the caller passes ``now`` and the samples (tested with a fake clock).
"""

from __future__ import annotations

import enum
import os
from dataclasses import dataclass

PF_EXITING = 0x4
"""The kernel's per-task flag (``include/linux/sched.h``), field 9 of ``/proc/<pid>/stat``."""
_CLOCK_TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


class Verdict(enum.Enum):
    """What the supervisor does about the tick now."""

    OK = "ok"
    """Beating within the threshold (or within it after the discounts): nothing."""
    STALLED = "stalled"
    """Older than the threshold, but the host, not the tick, explains it: counted, not punished."""
    STARTING = "starting"
    """No heartbeat yet and still making progress: waited for."""
    HUNG = "hung"
    """Stuck: fail over."""
    DYING = "dying"
    """Being torn down (killed, or exiting): fail over now, without waiting for its sentinel."""
    NEVER_STARTED = "never_started"
    """No heartbeat and no progress for ``start_stuck`` (or past ``start_limit``): fail over."""


@dataclass(frozen=True)
class Sched:
    """One sample of a process's scheduling (``/proc/<pid>/schedstat`` and ``stat``)."""

    cpu: float
    """Seconds on a CPU so far (the main thread: the tick's loop)."""
    wait: float
    """Seconds runnable but waiting on a run queue so far (the main thread)."""
    stopped: bool
    """State ``T`` or ``t``: stopped by a signal or a tracer."""
    process_cpu: float = 0.0
    """Seconds on a CPU so far, every thread (``utime + stime``, 10 ms steps): a spare's
    warm-up runs in a thread of its own."""
    exiting: bool = False
    """``PF_EXITING``: the process is being torn down (a SIGKILL, an exit) and runs none of its
    code any more; its sentinel becomes readable only once its memory is released, tens of
    milliseconds later for a large process on a busy host."""


@dataclass(frozen=True)
class Model:
    """Thresholds, seconds."""

    threshold: float
    """Heartbeat age (after the discounts) that makes a tick hung."""
    longest_excuse: float = 5.0
    """A tick starved longer than this is hung anyway."""
    start_stuck: float = 10.0
    """A starting tick that made no progress (CPU, run-queue wait) for this long never started."""
    start_limit: float = 300.0
    """A starting tick that has not beaten after this long never started, progress or not."""


@dataclass(frozen=True)
class Observation:
    """What the supervisor saw at ``now`` (seconds)."""

    now: float
    woke_late: float
    """How late the supervisor itself woke for this check (s, >= 0)."""
    beat_age: float | None
    """Age of the tick's last heartbeat; None before its first."""
    since_start: float
    """Seconds since this tick was started (or took over)."""
    at_beat: Sched | None
    """The tick's scheduling when its last heartbeat was seen (or at its start); None: unknown."""
    sched: Sched | None
    """The tick's scheduling now; None: unknown (no /proc, a thread)."""
    others_stall: float = 0.0
    """How long other processes' heartbeats (the guardian's) stalled over the same time (s)."""
    stolen: float = 0.0
    """The largest one-CPU steal time since about the last beat (s, ``devices/stall.py``'s
    reading of ``/proc/stat``): the hypervisor took the vCPU, nothing in the guest ran."""
    progress_age: float = 0.0
    """Starting only: seconds since the tick's CPU time or run-queue wait last grew."""


@dataclass(frozen=True)
class Finding:
    """A verdict and the numbers behind it (for the log and the status)."""

    verdict: Verdict
    age: float = 0.0
    """The heartbeat age after the discounts (s)."""
    excused: float = 0.0
    """The discount applied (s)."""
    why: str = ""


def classify(model: Model, seen: Observation) -> Finding:
    """The verdict on one observation (see the module docstring)."""
    if seen.sched is not None and seen.sched.exiting:
        return Finding(Verdict.DYING, why="exiting")
    if seen.beat_age is None:
        if seen.since_start > model.start_limit:
            return Finding(Verdict.NEVER_STARTED, why=f"never started ticking in {model.start_limit:.0f} s")
        if seen.sched is not None and seen.sched.stopped:
            return _starting_stopped(model, seen)
        if seen.progress_age > model.start_stuck:
            why = f"never started ticking: no progress for {seen.progress_age:.0f} s"
            return Finding(Verdict.NEVER_STARTED, why=why)
        return Finding(Verdict.STARTING)
    age = seen.beat_age
    if age <= model.threshold:
        return Finding(Verdict.OK, age)
    stopped = seen.sched is not None and seen.sched.stopped
    starved = 0.0
    if not stopped and seen.sched is not None and seen.at_beat is not None:
        starved = max(0.0, seen.sched.wait - seen.at_beat.wait)
    others = 0.0 if stopped else max(0.0, seen.others_stall, seen.stolen)
    excused = min(max(seen.woke_late, starved, others), age)
    left = age - excused
    if left > model.threshold:
        what = "stopped (SIGSTOP)" if stopped else "no heartbeat"
        why = f"hung ({what} for {age * 1000:.0f} ms, {excused * 1000:.0f} of them excused)"
        return Finding(Verdict.HUNG, left, excused, why)
    if excused > model.longest_excuse:
        return Finding(Verdict.HUNG, left, excused, f"hung (starved by the host for {excused:.1f} s)")
    return Finding(Verdict.STALLED, left, excused, f"host stall of {age * 1000:.0f} ms ({excused * 1000:.0f} excused)")


def _starting_stopped(model: Model, seen: Observation) -> Finding:
    """A starting tick that is stopped makes no progress: as stuck once ``start_stuck`` passed."""
    if seen.progress_age > model.start_stuck:
        return Finding(Verdict.NEVER_STARTED, why=f"never started ticking: stopped for {seen.progress_age:.0f} s")
    return Finding(Verdict.STARTING)


def read_sched(pid: int) -> Sched | None:
    """The I/O edge: ``pid``'s main thread from ``/proc`` (None when it is gone or there is no /proc)."""
    try:
        with open(f"/proc/{pid}/schedstat", "rb") as f:
            cpu_ns, wait_ns, *_ = f.read().split()
        with open(f"/proc/{pid}/stat", "rb") as f:
            stat = f.read()
    except (OSError, ValueError):
        return None
    fields = stat[stat.rindex(b")") + 2 :].split()  # the name may hold spaces and parentheses
    state, flags = fields[0], int(fields[6])
    process_cpu = (int(fields[11]) + int(fields[12])) / _CLOCK_TICKS
    stopped, exiting = state in (b"T", b"t"), bool(flags & PF_EXITING)
    return Sched(int(cpu_ns) / 1e9, int(wait_ns) / 1e9, stopped, process_cpu, exiting)
