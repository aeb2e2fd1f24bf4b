"""What the supervisor sees of the serving tick at each look: an :class:`~riderlive.service.stall.Observation`.

The heartbeat on the safety board, the tick's scheduling from ``/proc`` (CPU time, run-queue
wait, being torn down), the CPUs' steal since the last beat and the guardian's heartbeat;
``service/stall.py`` classifies it (pure), the supervisor acts on the verdict.
"""

from __future__ import annotations

from riderlive.devices.guardian import POLL_S
from riderlive.devices.stall import HostClock
from riderlive.service import stall

STEAL_BASE_S = 0.02
"""The CPUs' baseline (steal, accounted time) is taken at a new beat at most this often (it may
then count up to this much steal from before the beat: lenient by that, at ~50 us a read)."""
FROZEN_SLACK_S = 0.03
"""What a CPU's accounted time may fall short of the wall clock without its vCPU having been
taken: ``/proc/stat`` counts in 10 ms units, each field rounded down on its own. Chosen below
the counters' worst case (``devices.stall.accounting_error_s``: 80 ms, seven fields and a
kernel tick; seen 10 ms here, 30 ms in CI) so that a vCPU taken for 100 ms still excuses
70 ms of a late beat: the price, a CPU never taken may excuse up to 50 ms, and only of a
beat already late, never a tick that spins on a CPU that runs (its CPU keeps accounting)."""


class BeatWatch:
    """One generation's heartbeat as seen by the supervisor (:meth:`reset` at each new generation)."""

    def __init__(self, period: float, started_at: float) -> None:
        self.period = period
        """The tick's period (s): only a beat older than two of them pays for reading the steal."""
        self.beats_unread = 0
        """Heartbeat reads of 0 after the generation's first beat (should stay 0; see :meth:`observe`)."""
        self._host = HostClock()
        self._cpu_base: tuple[float, tuple[tuple[float, float], ...]] = (0.0, ())
        """When, and each CPU's (accounted, steal) seconds then, taken at most every ``STEAL_BASE_S`` at a new beat."""
        self.reset(started_at)

    def reset(self, started_at: float) -> None:
        """A new generation, started at ``started_at`` (perf_counter s)."""
        self.started_at = started_at
        self.beaten = False
        self._last_beat = 0.0
        """When the last heartbeat seen was written (perf_counter s)."""
        self._beat_value = 0.0
        self._at_beat: stall.Sched | None = None
        self._progress: tuple[float, float, float] = (started_at, -1.0, -1.0)
        """Starting tick: (when it last made progress, its CPU s, its wait s then)."""

    def observe(
        self,
        now: float,
        woke_late: float,
        beat: float,
        pid: int,
        guardian_beat: float,
        *,
        io: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> stall.Observation:
        """One look at ``now``: ``beat`` the board's heartbeat (0: none yet), ``pid`` the tick's,
        ``guardian_beat`` the guardian's (0: no guardian), ``io`` the tick's declared device waits
        (the ongoing one's deadline, 0: none, and start; the seconds of those ended since the beat).
        Sets :attr:`beaten` at the first beat."""
        sched = stall.read_sched(pid) if pid else None
        age: float | None = None
        if beat:
            age = max(0.0, now - beat)
            if beat != self._beat_value:
                self._beat_value, self._last_beat, self._at_beat = beat, beat, sched
                if now - self._cpu_base[0] > STEAL_BASE_S:
                    self._cpu_base = (now, self._host.cpu_seconds())
            self.beaten = True
        elif self.beaten:
            # A generation that has beaten never reads "no beat" again (only a promotion clears
            # it), yet one CI run restarted a ticking tick as "never started": counted, and the
            # age is taken from the last beat seen (a hang still shows).
            self.beats_unread += 1
            age = now - self._last_beat
        if age is None and sched is not None:
            _, cpu, wait = self._progress
            if sched.process_cpu > cpu or sched.wait > wait:
                self._progress = (now, sched.process_cpu, sched.wait)
        stolen = frozen = 0.0
        if age is not None and age > self.period * 2:  # only a late beat pays the read (~50 us)
            stolen, frozen = cpu_stalls(self._cpu_base, (now, self._host.cpu_seconds()), sched)
        return stall.Observation(
            now=now,
            woke_late=woke_late,
            beat_age=age,
            since_start=now - self.started_at,
            at_beat=self._at_beat,
            sched=sched,
            others_stall=max(0.0, now - guardian_beat - 2 * POLL_S) if guardian_beat else 0.0,
            stolen=stolen,
            frozen=frozen,
            progress_age=now - self._progress[0],
            io_until=io[0],
            io_since=io[1],
            io_waited=io[2] if beat else 0.0,
        )


CpuReading = tuple[float, tuple[tuple[float, float], ...]]
"""When (s) and each CPU's (accounted, steal) seconds (``devices.stall.HostClock.cpu_seconds``)."""


def cpu_stalls(base: CpuReading, now: CpuReading, sched: stall.Sched | None) -> tuple[float, float]:
    """(the largest one-CPU steal, the time the tick's CPU stood still) between two readings (s).

    A vCPU the hypervisor took accounts nothing until it runs again (``parse_cpu_seconds``):
    the wall time between the readings less the time that CPU accounted, less
    :data:`FROZEN_SLACK_S`, is how long it stood still; 0 when the tick's CPU is unknown."""
    (t0, before), (t1, after) = base, now
    pairs = list(zip(before, after, strict=False))
    stolen = max((b[1] - a[1] for a, b in pairs), default=0.0)
    cpu = sched.processor if sched is not None else -1
    if not 0 <= cpu < len(pairs) or t0 <= 0.0:
        return max(0.0, stolen), 0.0
    accounted = pairs[cpu][1][0] - pairs[cpu][0][0]
    return max(0.0, stolen), max(0.0, (t1 - t0) - accounted - FROZEN_SLACK_S)
