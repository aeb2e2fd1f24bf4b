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
  same time, the largest one-CPU steal time (a 2-vCPU guest's hypervisor takes a
  whole vCPU for ~100 ms: ``riderlive.devices.stall``, whose reading is used), and the
  time the tick's own CPU stood still: the guest adds steal only once the vCPU runs
  again, so during such a stall the steal reads 0, but the vCPU's accounted time
  (``/proc/stat``) stops; a tick asleep there is not woken (its timer is that CPU's) and
  one running there is not run (measured: 107-116 ms of standing still seen from the
  other vCPU, the 100 ms of steal added after; docs/hardware.md "A busy host"). What is
  left is measured against the threshold.
- **stopped** (``T`` in ``/proc/<pid>/stat``, a SIGSTOP): nothing excuses it but the
  supervisor's own lateness.
- **starved** for longer than ``Model.longest_excuse``: hung after all (killing it will
  not help much, but a tick nobody runs for that long is out of service).
- **dying** (``PF_EXITING``): a kill the sentinel will tell only once the process's memory
  is released: failed over at once.
- **waiting on device I/O** (:attr:`Verdict.IO_WAIT`): the tick declares on the safety
  board each bounded wait for a device's bytes (``devices/iowait.py``: the wait's start and
  deadline D while it lasts, then the seconds of such waits since its last beat). That
  time is discounted too, the part of an ongoing wait only up to D (so an age is never
  excused past D + the threshold), in all at most ``Model.io_limit``, and only when the
  tick is not spinning (its main thread asleep, ``S``/``D``, or on a CPU for under half
  the age: a wait polls its port every 0.2 ms). A gap that only this discount brings under
  the threshold is ``IO_WAIT``: counted, not punished. The device layer's own budgets
  (reply budget, Bus Watchdog) keep judging the servos.
- **runnable, not run**: ``/proc/<pid>/schedstat`` adds a run-queue wait only when the
  thread gets the CPU, so a tick runnable (``R``) but not run since its beat shows none
  (the soak saw a SCHED_FIFO 50 tick ``R`` with 0.0 ms on a CPU for 97 ms, behind other
  real-time work): a tick ``R`` that ran under a tenth of the age is discounted the age
  minus what it ran.
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
    IO_WAIT = "io_wait"
    """Older than the threshold inside a declared, bounded device wait, asleep: counted, not punished."""
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
    state: str = ""
    """The main thread's state letter (``R`` running, ``S`` asleep, ``D`` in uninterruptible I/O...)."""
    processor: int = -1
    """The CPU the main thread last ran on (``/proc/<pid>/stat`` field 39; -1: unknown)."""


@dataclass(frozen=True)
class Model:
    """Thresholds, seconds."""

    threshold: float
    """Heartbeat age (after the discounts) that makes a tick hung."""
    io_limit: float = 0.0
    """The most declared device waits can excuse of one gap (s; 0: the threshold)."""
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
    frozen: float = 0.0
    """Seconds since about the last beat that the tick's CPU accounted no time at all (its
    vCPU taken: ``service/watch.py`` reads it from ``/proc/stat``, less its resolution)."""
    progress_age: float = 0.0
    """Starting only: seconds since the tick's CPU time or run-queue wait last grew."""
    io_until: float = 0.0
    """The deadline of the device wait the tick is in (same clock as ``now``; 0: none)."""
    io_since: float = 0.0
    """When that wait began (same clock)."""
    io_waited: float = 0.0
    """Seconds of declared device waits that ended since the tick's last beat."""


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
        ran = seen.sched.cpu - seen.at_beat.cpu
        starved = max(0.0, seen.sched.wait - seen.at_beat.wait)
        if seen.sched.state == "R" and ran < 0.1 * age:  # runnable, not run: schedstat counts it later
            starved = max(starved, age - ran)
    others = 0.0 if stopped else max(0.0, seen.others_stall, seen.stolen, seen.frozen)
    excused = min(max(seen.woke_late, starved, others), age)
    left = age - excused
    io = 0.0 if stopped else io_excuse(model, seen)
    if left > model.threshold and age - max(excused, io) <= model.threshold:
        why = f"waiting on device I/O: {age * 1000:.0f} ms since the beat, {io * 1000:.0f} of them in declared waits"
        return Finding(Verdict.IO_WAIT, age - max(excused, io), max(excused, io), why)
    if left > model.threshold:
        what = "stopped (SIGSTOP)" if stopped else "no heartbeat"
        why = f"hung ({what} for {age * 1000:.0f} ms, {excused * 1000:.0f} of them excused)"
        return Finding(Verdict.HUNG, left, excused, why)
    if excused > model.longest_excuse:
        return Finding(Verdict.HUNG, left, excused, f"hung (starved by the host for {excused:.1f} s)")
    return Finding(Verdict.STALLED, left, excused, f"host stall of {age * 1000:.0f} ms ({excused * 1000:.0f} excused)")


def io_excuse(model: Model, seen: Observation) -> float:
    """Seconds of the gap spent in declared device waits, ended or ongoing (up to their
    deadline), at most ``Model.io_limit``; 0 when the tick spins (see the module docstring)."""
    sched, at_beat, age = seen.sched, seen.at_beat, seen.beat_age or 0.0
    if sched is None:
        return 0.0
    if sched.state not in ("S", "D") and (at_beat is None or sched.cpu - at_beat.cpu >= 0.5 * age):
        return 0.0
    ongoing = max(0.0, min(seen.now, seen.io_until) - seen.io_since) if seen.io_until else 0.0
    return min(seen.io_waited + ongoing, age, model.io_limit or model.threshold)


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
    processor = int(fields[36]) if len(fields) > 36 else -1
    return Sched(int(cpu_ns) / 1e9, int(wait_ns) / 1e9, stopped, process_cpu, exiting, state.decode(), processor)


@dataclass(frozen=True)
class ThreadState:
    """One thread of the tick at a verdict: ``/proc/<pid>/task/<tid>/{stat,wchan,schedstat}``."""

    tid: int
    name: str
    state: str
    """``R`` running or runnable, ``S`` asleep, ``D`` uninterruptible (I/O), ``T`` stopped..."""
    wchan: str
    """The kernel function it sleeps in (``do_select``, ``futex_wait_queue``...; ``0``: running)."""
    cpu: float
    """Seconds on a CPU so far."""
    wait: float
    """Seconds runnable on a run queue so far."""
    syscall: str = ""
    """``/proc/.../syscall``: the system call it is in and its arguments in hex (``running``:
    none); e.g. a ``select`` (23 on x86-64) with a write set and no timeout (0) is pyserial
    waiting for a port to take bytes."""


def read_threads(pid: int) -> list[ThreadState]:
    """Every thread of ``pid`` (its main thread first); [] when it is gone. Read only at a
    verdict past the threshold (a few hundred microseconds for a handful of threads)."""
    try:
        tids = sorted(int(t) for t in os.listdir(f"/proc/{pid}/task"))
    except (OSError, ValueError):
        return []
    out = []
    for tid in sorted(tids, key=lambda t: t != pid):
        base = f"/proc/{pid}/task/{tid}"
        try:
            with open(f"{base}/stat", "rb") as f:
                stat = f.read()
            with open(f"{base}/wchan", "rb") as f:
                wchan = f.read().decode(errors="replace").strip() or "0"
            with open(f"{base}/schedstat", "rb") as f:
                cpu_ns, wait_ns, *_ = f.read().split()
        except (OSError, ValueError):
            continue
        try:
            with open(f"{base}/syscall", "rb") as f:
                syscall = " ".join(f.read().decode(errors="replace").split()[:6])
        except OSError:
            syscall = ""
        name = stat[stat.index(b"(") + 1 : stat.rindex(b")")].decode(errors="replace")
        state = stat[stat.rindex(b")") + 2 :].split()[0].decode()
        out.append(ThreadState(tid, name, state, wchan, int(cpu_ns) / 1e9, int(wait_ns) / 1e9, syscall))
    return out


def describe_threads(threads: list[ThreadState], at_beat: Sched | None) -> str:
    """What the tick was doing, for a verdict's log line and the status: its main thread's
    state, kernel wait channel, CPU and run-queue time since the last beat; the others' states."""
    if not threads:
        return "threads: gone"
    main, rest = threads[0], threads[1:]
    text = f"main thread {main.state} in {main.wchan}" + (f" (syscall {main.syscall})" if main.syscall else "")
    if at_beat is not None:
        ran, waited = (main.cpu - at_beat.cpu) * 1000, (main.wait - at_beat.wait) * 1000
        text += f", since the beat ran {ran:.1f} ms, runnable unrun {waited:.1f} ms"
    others: dict[str, int] = {}
    for t in rest:
        key = f"{t.state} {t.wchan}"
        others[key] = others.get(key, 0) + 1
    if others:
        text += "; other threads: " + ", ".join(f"{n} x {k}" for k, n in sorted(others.items()))
    return text


@dataclass
class Tally:
    """The verdicts that were counted, not punished (the supervision status), one count per
    heartbeat gap; and what the tick was doing at the last hang."""

    stalls: int = 0
    """Gaps past the threshold that the host explained."""
    stall_excused_max: float = 0.0
    """The largest such gap's excused part (s)."""
    io_waits_excused: int = 0
    """Gaps past the threshold inside a declared device wait (:attr:`Verdict.IO_WAIT`)."""
    io_wait_longest: float = 0.0
    """The oldest heartbeat a declared device wait excused (s)."""
    last_hang: str = ""
    """The last hang verdict and the tick's threads then (:func:`describe_threads`)."""
    _gap: float = -1.0
    _counted: frozenset[Verdict] = frozenset()

    def add(self, finding: Finding, beat: float, age: float) -> str | None:
        """Count ``finding`` (STALLED or IO_WAIT) for the gap after the beat ``beat``, whose
        raw age is ``age`` (s); the line to log at its first count, else None."""
        if beat != self._gap:
            self._gap, self._counted = beat, frozenset()
        first = finding.verdict not in self._counted
        self._counted |= {finding.verdict}
        if finding.verdict is Verdict.IO_WAIT:
            self.io_wait_longest = max(self.io_wait_longest, age)
            self.io_waits_excused += first
            return f"the tick is waiting on a device, not hung: {finding.why}" if first else None
        if finding.verdict is Verdict.STALLED:
            self.stall_excused_max = max(self.stall_excused_max, finding.excused)
            self.stalls += first
            return f"the tick is late, not hung: {finding.why}" if first else None
        return None

    def snapshot(self) -> dict[str, float | int | str]:
        return {
            "stalls": self.stalls,
            "stall_excused_max": self.stall_excused_max,
            "io_waits_excused": self.io_waits_excused,
            "io_wait_longest": self.io_wait_longest,
            "last_hang": self.last_hang,
        }


def hang_detail(finding: Finding, seen: Observation, pid: int) -> str:
    """A hang verdict's reason with what the tick was doing then (its threads from ``/proc``,
    the device wait it had declared): read only at a hang, once."""
    text = f"{finding.why}; {describe_threads(read_threads(pid), seen.at_beat) if pid else 'no pid'}"
    if seen.io_waited:
        text += f"; {seen.io_waited * 1000:.1f} ms in device waits that ended since the beat"
    if seen.io_until:
        since, until = (seen.io_since - seen.now) * 1000, (seen.io_until - seen.now) * 1000
        text += f"; in a device wait declared from {since:+.1f} ms until {until:+.1f} ms"
    if seen.sched is not None and seen.sched.processor >= 0:
        text += f"; on CPU {seen.sched.processor}, which stood still {seen.frozen * 1000:.0f} ms"
        text += f" (steal {seen.stolen * 1000:.0f} ms)"
    return text
