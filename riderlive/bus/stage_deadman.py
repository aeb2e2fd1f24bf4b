"""The stage dead-man of a rig on a stage (``bus/rig.py``).

Without a stage heartbeat for ``timeout`` seconds, an armed rig is disarmed: its devices
ease to park, then torque off (the lifecycle's controlled stop, category 1); arming is
refused until the heartbeat is back, and nothing re-arms when it returns. A broker that
dies, a cut cable, a stopped heartbeat source all look the same.

It runs in a task of its own and does no broker I/O: a status publish that waits on a
dead broker, or raises, cannot delay or end it (it once shared a loop with that publish).
A look that raises is logged and counted (``deadman_errors``), and the next look comes
``interval`` s later: the watch ends only when its task is cancelled. A disarm the tick
refuses while something is still armed escalates to an e-stop (category 0).

Times are ``time.perf_counter()`` seconds (the clock is injectable for tests).
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import Counter
from collections.abc import Awaitable, Callable

log = logging.getLogger("riderlive.bus.rig")


class StageDeadMan:
    """See the module docstring. ``beat`` on each heartbeat; ``run`` in a task of its own.

    Narrow collaborators: ``armed()`` is some device armed now; ``disarm(by)`` asks the
    tick to disarm every device and returns None when it agreed, else its refusal; ``estop()`` latches the
    e-stop. ``counts`` is the rig node's event counter (``riderlive_nats_events_total``)."""

    def __init__(
        self,
        timeout: float,
        stage: str,
        *,
        armed: Callable[[], bool],
        disarm: Callable[[str], Awaitable[str | None]],
        estop: Callable[[], object],
        counts: Counter[str],
        clock: Callable[[], float] = time.perf_counter,
    ) -> None:
        self.timeout = timeout
        """Seconds without a heartbeat that stop the rig; 0 turns the dead-man off."""
        self.stage = stage
        self.armed, self.disarm, self.estop = armed, disarm, estop
        self.counts = counts
        self.clock = clock
        self.started = clock()
        self.last_heartbeat: float | None = None
        self.lost = False

    @property
    def interval(self) -> float:
        """Seconds between looks: a fifth of the timeout, at most 50 ms."""
        return min(0.05, self.timeout / 5.0) if self.timeout > 0.0 else 0.05

    def beat(self) -> None:
        """A stage heartbeat arrived now."""
        self.last_heartbeat = self.clock()

    def age(self, now: float) -> float:
        """Seconds since the last heartbeat (since joining when none was heard yet)."""
        return now - (self.started if self.last_heartbeat is None else self.last_heartbeat)

    def arm_refusal(self) -> str | None:
        """Why arming must wait (no stage heartbeat), or None."""
        if self.timeout > 0.0 and (self.last_heartbeat is None or self.age(self.clock()) > self.timeout):
            return (
                f"no stage heartbeat within {self.timeout:g} s on stage {self.stage!r} "
                "(run `riderlive stage heartbeat`): arming refused"
            )
        return None

    async def look(self) -> None:
        """One look: note a loss or a return; while lost, disarm what is armed."""
        now = self.clock()
        lost = self.age(now) > self.timeout
        if lost != self.lost:
            self.lost = lost
            self.counts["heartbeat_lost" if lost else "heartbeat_back"] += 1
            said = "lost: armed devices park, arming refused" if lost else "back (nothing re-arms)"
            log.warning("stage heartbeat %s", said)
        if not lost or not self.armed():
            return
        self.counts["heartbeat_stops"] += 1
        refused = await self.disarm(f"stage heartbeat lost ({self.age(now):.2f} s)")
        if refused is not None and self.armed():
            log.critical("the heartbeat stop was refused (%s): e-stop", refused)
            self.estop()

    async def run(self) -> None:
        """Look every ``interval`` s until cancelled (off when ``timeout`` is 0)."""
        if self.timeout <= 0.0:
            return
        while True:
            await asyncio.sleep(self.interval)
            try:
                await self.look()
            except Exception:  # a look that raised must not end the dead-man
                self.counts["deadman_errors"] += 1
                log.exception("the stage dead-man's look failed (counted; it looks again)")
