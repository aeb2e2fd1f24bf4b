"""The safety board: what the guardian must know when a controller dies.

One shared-memory segment of float64 slots, written by several processes, each slot
by exactly one of them:

- the web process: its pid and heartbeat, the tick's pid and generation (a new
  generation per spawn), the generation whose devices the guardian must hand back
  before the serving one's devices open their transports (``handback_from``), ``shutdown``;
- the tick: its heartbeat (every tick), a clean-exit mark, and per device its state
  and its last goal pose (seqlock'd: the guardian never reads a torn pose); while a
  guardian stops a dead tick's devices, the guardian (so a successor, should it die
  too, eases on from where the park had got, not from the dead tick's pose);
- the guardian: its pid and heartbeat (from its first instant: imports come after),
  ``ready`` once its plugs are built, the last generation it has stopped, ``busy``
  while it holds a bus, takeovers done, and per device what it did in its last stop
  (:class:`GuardianReport`: what the web process shows for a device while no tick
  generation is serving), and the last generation whose stop it has begun
  (``guardian_taking``: from then the next generation may tick while the park goes on,
  its devices waiting for ``guardian_done`` to reach the web's ``handback_from``
  before they open a transport; ``devices/guardians.py``); a standby guardian its pid (``guardian_standby``) once its
  plugs are built, until it becomes the guardian (the beat, then the pid).

The tick watches the guardian as the guardian watches the tick (:func:`guardian_watching`).

Times are ``perf_counter`` seconds (CLOCK_MONOTONIC, shared by every process here).
"""

from __future__ import annotations

import enum
from collections.abc import Sequence

from riderlive.devices.lifecycle import DeviceState
from riderlive.devices.shared import Slot, SlotBlock, Slots, pid_alive

GUARDIAN_HANG_S = 0.5
"""A guardian whose heartbeat (written every 5 ms by its watch loop) is older than this is
hung: armed devices get a category 1 stop from the tick, arming is refused. Generous
because the guardian may run at normal priority where the host does not permit SCHED_FIFO
(``guardian.priority``; a stall of tens of ms is normal there, 0.5 s is not); a dead
guardian is seen at once (its pid)."""
MAX_DEVICES = 4
MAX_UNITS = 64
STATES: tuple[DeviceState, ...] = tuple(DeviceState)


class GuardianReport(enum.IntEnum):
    """What the guardian did with a device in its last stop (``guardian_dN`` on the board)."""

    NONE = 0
    """Nothing yet (or the slot was cleared for a new generation)."""
    PARKING = 1
    """Taking over a device that was moving: easing it to park, then outputs off."""
    STOPPING = 2
    """Taking over a device that was not moving: outputs off, read back."""
    OUTPUTS_OFF = 3
    """Stopped: every unit read back with its outputs off."""
    UNCONFIRMED = 4
    """Outputs off sent but not confirmed by a read back (handed back or given up)."""
    UNREACHABLE = 5
    """The port was gone or held by another process: the servos' own watchdog is all that is left."""
    NOT_CONNECTED = 6
    """The dead tick had not connected it: nothing of ours on its bus."""


_DEVICE = ("state", "seq", "units")
_PER_DEVICE = len(_DEVICE) + MAX_UNITS


def _names() -> tuple[str, ...]:
    names = [*SafetyBoard.slot_names(), *(f"guardian_d{d}" for d in range(MAX_DEVICES))]
    for d in range(MAX_DEVICES):
        names += [f"d{d}.{k}" for k in _DEVICE] + [f"d{d}.pose{u}" for u in range(MAX_UNITS)]
    return tuple(names)


WEB = "the web process"
TICK = "the tick (every generation in turn)"
GUARDIAN = "the guardian"


class SafetyBoard(Slots, SlotBlock):
    """The board; ``SafetyBoard()`` creates it, ``SafetyBoard(name)`` attaches.

    The header's slots by attribute (each with the one process that writes it); per device,
    :meth:`publish` / :meth:`device` (the tick's state and pose, seqlock'd) and
    :meth:`report` / :meth:`reported` (the guardian's ``GuardianReport``)."""

    web_pid = Slot(int, WEB, "the web process's pid")
    web_beat = Slot(float, WEB, "perf_counter s of the web process's last beat")
    tick_pid = Slot(int, WEB, "the tick process's pid (0: none; set by the web process at each spawn or takeover)")
    tick_generation = Slot(int, WEB, "the serving tick's generation (1, 2... : +1 per spawn or takeover)")
    tick_beat = Slot(float, TICK, "perf_counter s of the tick's last beat (every tick; 0: a new generation)")
    tick_clean_exit = Slot(int, TICK, "the generation that stopped cleanly (the guardian has nothing to stop)")
    guardian_pid = Slot(int, GUARDIAN, "the watching guardian's pid (a standby writes it when it takes over)")
    guardian_beat = Slot(float, GUARDIAN, "perf_counter s of the guardian's last beat (every 5 ms)")
    guardian_ready = Slot(float, GUARDIAN, "1 once the guardian's plugs are built")
    guardian_done = Slot(int, GUARDIAN, "the last generation the guardian stopped (its buses handed back)")
    guardian_taking = Slot(
        int, GUARDIAN, "the last generation whose stop the guardian began (its tick killed, its devices' poses read)"
    )
    guardian_busy = Slot(float, GUARDIAN, "1 while the guardian holds a bus")
    guardian_takeovers = Slot(int, GUARDIAN, "stops the guardian made")
    guardian_standby = Slot(int, "the standby guardian", "the standby's pid once its plugs are built (0: none)")
    shutdown = Slot(float, WEB, "1: the service stops (the guardians exit)")
    handback_from = Slot(
        int, WEB, "the generation the guardian must hand back before the serving one opens a transport (0: none)"
    )
    tick_io_until = Slot(
        float, TICK, "perf_counter s until which the tick waits on a device's bytes (0: not waiting; devices/iowait.py)"
    )
    tick_io_since = Slot(float, TICK, "perf_counter s when that wait began")
    tick_io_waited = Slot(float, TICK, "seconds of device waits that ended since the tick's last beat")

    def __init__(self, name: str | None = None) -> None:
        super().__init__(_names(), name)
        self._reports = len(self.slots())
        """Index of ``guardian_d0`` (one :class:`GuardianReport` per device follows)."""
        self._base = self._reports + MAX_DEVICES

    def publish(self, device: int, state: DeviceState, pose: Sequence[float]) -> None:
        """The tick, once per tick per device: its state and last goal pose."""
        base = self._base + device * _PER_DEVICE
        values = self.values
        seq = values[base + 1]
        values[base + 1] = seq + 1.0  # odd: being written
        values[base] = float(STATES.index(state))
        n = min(len(pose), MAX_UNITS)
        values[base + 2] = float(n)
        for u in range(n):
            values[base + 3 + u] = pose[u]
        values[base + 1] = seq + 2.0

    def device(self, device: int) -> tuple[DeviceState, list[float]] | None:
        """A device's last published state and pose (None if never published)."""
        base = self._base + device * _PER_DEVICE
        values = self.values
        for _ in range(100):
            seq = values[base + 1]
            if seq == 0.0:
                return None
            if int(seq) % 2:
                continue
            state = STATES[int(values[base])]
            pose = [values[base + 3 + u] for u in range(int(values[base + 2]))]
            if values[base + 1] == seq:
                return state, pose
        return None

    def forget_devices(self) -> None:
        """Before a new tick starts: nothing published yet (the guardian must not park a
        device from a dead tick's old pose on the new tick's behalf)."""
        for device in range(MAX_DEVICES):
            self.values[self._base + device * _PER_DEVICE + 1] = 0.0

    def report(self, device: int, report: GuardianReport) -> None:
        """The guardian: what it is doing or did with ``device`` in its stop."""
        self.values[self._report_slot(device)] = float(report)

    def reported(self, device: int) -> GuardianReport:
        """What the guardian last reported for ``device``."""
        return GuardianReport(int(self.values[self._report_slot(device)]))

    def clear_reports(self) -> None:
        """The web process, when a generation fails: the guardian's reports are about it from now."""
        for device in range(MAX_DEVICES):
            self.values[self._report_slot(device)] = 0.0

    def _report_slot(self, device: int) -> int:
        if not 0 <= device < MAX_DEVICES:
            raise IndexError(f"device {device}: the board has slots for devices 0-{MAX_DEVICES - 1}")
        return self._reports + device


def guardian_watching(board: SafetyBoard, now: float) -> str | None:
    """None while a guardian is ready, its process alive and its heartbeat younger than
    ``GUARDIAN_HANG_S`` (``now``: perf_counter s); else why not, for the log and refusals."""
    pid = board.guardian_pid
    if not pid or not pid_alive(pid):
        return "no guardian (dead-man process) is running" if not pid else f"the guardian {pid} is dead"
    if board.guardian_ready != 1.0:
        return f"the guardian {pid} is starting"
    age = now - board.guardian_beat
    if age > GUARDIAN_HANG_S:
        return f"the guardian {pid} has not beaten for {age * 1000:.0f} ms (hung)"
    return None
