"""Fixed-rate pacing on ``perf_counter`` deadlines (real-time priority: :mod:`riderlive.sched`).

Deadline ``n`` is ``start + n * period``: it never drifts, whatever a tick costs.
The clock sleeps until about ``spin`` seconds before the deadline, then spins on
``perf_counter`` (a sleep alone wakes 50-100 us late, more under load). A tick that
starts more than one period late is an overrun; the deadlines it missed entirely
are skipped (counted) rather than run back to back.
"""

from __future__ import annotations

import select
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

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


PICKUP_GRACE = 0.0003
"""Seconds past its deadline the tick waits, at most, for an input the web process received
before the deadline but has not yet put in the input ring (at most 15 % of a period)."""
PICKUP_MAX_AGE = 0.001
"""An input received longer than this before the deadline and still not in the ring is not
waited for (a writer that died mid-frame leaves its note behind)."""


def pickup_until(deadline: float, received: float, period: float) -> float:
    """Until when (``perf_counter`` seconds) the tick waits at its pickup for the input the
    web process received at ``received`` (-1: none on its way) and is still turning into an
    input record; -1 when it does not wait.

    The web process stamps a frame, then decodes, converts and checks it (~0.05-0.3 ms on a
    busy host) before it writes the record: a frame received in that span before a deadline
    missed it and waited a whole period more (6-9 % of the frames at 500 Hz, the p99's tail).
    Waiting for it costs that tick up to the grace, and saves the frame a period."""
    if received < 0.0 or received > deadline or deadline - received > PICKUP_MAX_AGE:
        return -1.0
    return deadline + min(PICKUP_GRACE, 0.15 * period)


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
