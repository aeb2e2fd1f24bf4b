"""Fixed-rate pacing on ``perf_counter`` deadlines, and real-time priority.

Deadline ``n`` is ``start + n * period``: it never drifts, whatever a tick costs.
The clock sleeps until about ``spin`` seconds before the deadline, then spins on
``perf_counter`` (a sleep alone wakes 50-100 us late, more under load). A tick that
starts more than one period late is an overrun; the deadlines it missed entirely
are skipped (counted) rather than run back to back.
"""

from __future__ import annotations

import contextlib
import logging
import os
import select
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

log = logging.getLogger(__name__)

LATENESS_BUCKETS: tuple[float, ...] = (
    0.00005,
    0.0001,
    0.00025,
    0.0005,
    0.001,
    0.002,
    0.003,
    0.005,
    0.01,
    0.025,
    0.1,
)
"""Upper bounds (seconds) of the tick-lateness histogram; a last bucket is +Inf."""


def bucket_of(lateness: float) -> int:
    """Index of the histogram bucket holding ``lateness`` (len(LATENESS_BUCKETS) = +Inf)."""
    for i, bound in enumerate(LATENESS_BUCKETS):
        if lateness <= bound:
            return i
    return len(LATENESS_BUCKETS)


@dataclass
class DeadlineClock:
    """Waits for deadline after deadline; all times are ``perf_counter`` seconds."""

    period: float
    start: float
    spin: float = 0.001
    tick: int = 0
    """Index of the deadline last waited for."""
    overruns: int = 0
    skipped: int = 0

    def deadline(self, n: int) -> float:
        return self.start + n * self.period

    def wait(self) -> tuple[float, float]:
        """Wait for the next deadline; return ``(deadline, lateness)`` in seconds."""
        woke = self.wait_or_wake()
        assert woke is not None
        return woke

    def wait_or_wake(
        self, fds: Sequence[int] = (), interrupted: Callable[[], bool] | None = None
    ) -> tuple[float, float] | None:
        """Like :meth:`wait`, but return None as soon as one of ``fds`` is readable
        (while sleeping) or ``interrupted()`` is true (while spinning): the deadline is
        then still ahead, and the next call waits for it again. The caller must consume
        what made an fd readable."""
        target = self.deadline(self.tick + 1)
        now = time.perf_counter()
        if now - target > self.period:
            self.overruns += 1
            missed = int((now - target) / self.period)
            self.skipped += missed
            self.tick += missed
            target = self.deadline(self.tick + 1)
        remaining = target - now - self.spin
        if remaining > 0.0:
            if not fds:
                time.sleep(remaining)
            elif select.select(fds, [], [], remaining)[0]:
                return None
        while (now := time.perf_counter()) < target:
            if interrupted is not None and interrupted():
                return None
        self.tick += 1
        return target, now - target


def normal_priority_thread() -> None:
    """The calling thread at normal scheduling (Linux: per thread), e.g. the worker threads of a
    web process at SCHED_FIFO, so that a bake or an upload check never runs at real-time priority."""
    if hasattr(os, "sched_setscheduler"):
        try:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        except OSError as exc:  # already normal, or not permitted to change: it stays as it is
            log.debug("worker thread scheduling unchanged: %s", exc)


def try_realtime_priority(priority: int = 50, reset_on_fork: bool = False, who: str = "the tick") -> str:
    """Ask for SCHED_FIFO at ``priority``; return ``"fifo"`` or why not (and warn about ``who``).

    ``reset_on_fork``: processes started afterwards begin at normal scheduling."""
    if not hasattr(os, "sched_setscheduler"):
        log.warning("real-time priority is not available on this platform; %s runs at normal priority", who)
        return "unsupported"
    try:
        limit = os.sched_get_priority_max(os.SCHED_FIFO)
        policy = os.SCHED_FIFO | (os.SCHED_RESET_ON_FORK if reset_on_fork else 0)
        os.sched_setscheduler(0, policy, os.sched_param(min(priority, limit)))
    except PermissionError:
        log.warning(
            "SCHED_FIFO not permitted (run as root, or grant an rtprio limit in /etc/security/limits.conf); "
            "%s runs at normal priority and may be late under load",
            who,
        )
        return "denied"
    except OSError as exc:
        log.warning("SCHED_FIFO failed (%s); %s runs at normal priority", exc, who)
        return "failed"
    return "fifo"


def normal_priority() -> None:
    """This thread back to normal scheduling (after :func:`try_realtime_priority`)."""
    if hasattr(os, "sched_setscheduler"):
        with contextlib.suppress(OSError):
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
