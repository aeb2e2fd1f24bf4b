"""The guardian process and its standby, as the driving side keeps them (``devices/guardian.py``).

The guardian parks and releases the devices of a tick that died or hung; it lives
outside the tick so that it survives it. A **standby** guardian (imports paid, plugs
built) becomes the guardian within a few ms of its death: a relaunch would cost a
Python start and the imports. :class:`Guardians` launches both, relaunches what died
(at most one launch a second), reports their state and says when the guardian has
begun (:meth:`Guardians.taken`) and ended (:meth:`Guardians.stopped`) the stop of a
generation's devices; :func:`handback_pending` tells the next generation's devices
(in the tick) whether they must wait for that stop's end before opening a transport.
Kept by the web process's supervisor (``service/supervisor.py``) and by
``riderlive rig --drive`` (``riderlive/rig_drive.py``).
"""

from __future__ import annotations

import logging
import subprocess
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from riderlive.devices.board import SafetyBoard, guardian_watching
from riderlive.devices.guardian import GIVE_UP_AFTER_S, launch
from riderlive.devices.registry import DeviceSpec

log = logging.getLogger("riderlive.guardians")
START_S = 5.0
"""Allowance for a guardian relaunched during a stop to start and finish it (its imports
on a loaded host), on top of the park timeout."""
RELAUNCH_S = 1.0
"""At most one launch this often (s)."""


@dataclass(frozen=True)
class GuardianTimes:
    """The guardian's thresholds (s): a tick or web process whose heartbeat is older is
    failed; with nobody to hand a bus back to, an unconfirmed outputs-off is given up after
    ``give_up``. ``web_timeout`` is unused where there is no web process (``web_pid`` 0).
    ``priority``: SCHED_FIFO of the guardian and its standby once ready (0: normal)."""

    tick_timeout: float
    web_timeout: float
    give_up: float = GIVE_UP_AFTER_S
    priority: int = 0


class Guardians:
    """The guardian and its standby for ``specs``, on ``board`` (see the module docstring)."""

    def __init__(self, board: SafetyBoard, latch_name: str, specs: Sequence[DeviceSpec], times: GuardianTimes) -> None:
        self.board = board
        self.latch_name = latch_name
        self.specs = tuple(specs)
        self.times = times
        self.guardian: subprocess.Popen[bytes] | None = None
        self.standby: subprocess.Popen[bytes] | None = None
        """A standby guardian: becomes the guardian the moment it is gone (guardian.py)."""
        self.restarts = 0
        self._launched_at = 0.0

    def _launch(self, standby_after: int = 0) -> subprocess.Popen[bytes]:
        times = self.times
        return launch(
            self.board.name,
            self.latch_name,
            self.specs,
            times.tick_timeout,
            times.web_timeout,
            give_up_s=times.give_up,
            standby_after=standby_after,
            priority=times.priority,
        )

    def start(self) -> None:
        """The guardian, and a standby watching it."""
        self.guardian = self._launch()
        self._launched_at = time.perf_counter()
        self.standby = self._launch(standby_after=self.guardian.pid)

    def check(self, now: float) -> None:
        """The guardian gone: its standby has taken over (or it is relaunched); a new standby
        follows (at most one launch a second). ``now``: perf_counter s."""
        if self.guardian is None:
            return
        if self.guardian.poll() is not None:
            code = self.guardian.returncode
            if self.standby is not None and self.standby.poll() is None:
                log.critical("the guardian exited (%s): its standby %d takes over", code, self.standby.pid)
                self.guardian, self.standby = self.standby, None
            elif now - self._launched_at >= RELAUNCH_S:
                log.critical("the guardian exited (%s), no standby: relaunching it; arming is refused", code)
                self.board.guardian_ready = 0.0
                self.guardian, self.standby = self._launch(), None
                self._launched_at = now
            else:
                return
            self.restarts += 1
        if (self.standby is None or self.standby.poll() is not None) and now - self._launched_at >= RELAUNCH_S:
            self.standby = self._launch(standby_after=self.guardian.pid)
            self._launched_at = now

    def alive(self) -> bool:
        """Ready, its process alive, its heartbeat fresh (the tick's own test: board.guardian_watching)."""
        return self.guardian is not None and guardian_watching(self.board, time.perf_counter()) is None

    def ready(self) -> str | None:
        """None once the launched guardian is ready; else why not (still starting, or exited)."""
        if self.guardian is None:
            return "no guardian was launched"
        if self.guardian.poll() is not None:
            return f"the guardian exited ({self.guardian.returncode}) before it was ready"
        return None if self.board.guardian_ready == 1.0 else "the guardian is starting"

    def stopped(self, generation: int) -> bool:
        """The guardian has stopped the devices of tick ``generation`` (or none is kept)."""
        return self.guardian is None or self.board.guardian_done >= generation

    def taken(self, generation: int) -> bool:
        """The guardian has begun the stop of tick ``generation`` (killed it, read its devices'
        last poses) or ended it, or none is kept: the next generation may start ticking."""
        board = self.board
        return self.guardian is None or max(board.guardian_taking, board.guardian_done) >= generation

    def stop_wait_s(self, park_timeout: float) -> float:
        """How long a failover waits for :meth:`taken` (s): see :func:`stop_wait_s`."""
        return stop_wait_s(park_timeout)

    def stop(self) -> None:
        """After the tick has stopped (its devices are closed): the guardians may go."""
        self.board.shutdown = 1.0
        for guardian in (self.guardian, self.standby):
            if guardian is not None:
                try:
                    guardian.wait(2.0)
                except subprocess.TimeoutExpired:
                    guardian.kill()
                    guardian.wait(2.0)

    def snapshot(self, enabled: bool) -> dict[str, Any]:
        guardian, standby = self.guardian, self.standby
        return {
            "enabled": enabled,
            "alive": self.alive(),
            "pid": None if guardian is None else guardian.pid,
            "standby_pid": None if standby is None or standby.poll() is not None else standby.pid,
            "standby_ready": standby is not None and self.board.guardian_standby == standby.pid,
            "restarts": self.restarts,
            "takeovers": self.board.guardian_takeovers,
        }


def stop_wait_s(park_timeout: float) -> float:
    """The longest a guardian's stop may take to begin or to end (s): a park
    (``park_timeout`` s), its read-back, and a relaunch of the guardian meanwhile."""
    return park_timeout + 3.0 + START_S


def handback_wanted(generation: int, taken: bool, stopped: bool) -> int:
    """What the web process writes to ``board.handback_from`` when it promotes the next tick
    after generation ``generation`` failed: that generation while a guardian has begun its
    stop and not ended it (the new devices wait for the hand-back); 0 once it has ended, or
    when no guardian began it in time (nobody parks then: the new devices connect at once
    and their setup turns the outputs off, a category 0 stop, rather than leave the rig
    holding its last goal with torque on)."""
    return generation if taken and not stopped else 0


def handback_pending(board: SafetyBoard, device: int) -> str | None:
    """For device ``device`` of the serving tick: why it must not open its transport yet
    (the guardian has not handed back generation ``board.handback_from``'s devices: it may
    still be parking them, or not have taken them yet); None once it may. The flock on the
    port is not enough: a dead tick's lock can be released before the guardian takes the
    port, and a connect's outputs-off in the middle of a park would drop the rig."""
    wanted = int(board.handback_from)
    if not wanted or board.guardian_done >= wanted:
        return None
    doing = board.reported(device).name.lower().replace("_", " ")
    return f"waiting for the guardian to park and hand back generation {wanted} (guardian: {doing})"
