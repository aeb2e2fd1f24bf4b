"""Keeping a warm spare tick beside the serving one (``realtime/spare.py`` is the spare itself).

A spare is started once the serving generation has beaten (none while a tick starts: it
would take its CPU) and whenever the last one is gone; one that failed its warm-up or
died is replaced after ``SPARE_RETRY_S``, doubling per failure in a row up to 60 s.
"""

from __future__ import annotations

import logging
from typing import Any

from riderlive.realtime.link import TickLink, exit_reason

log = logging.getLogger("riderlive.service.supervisor")
SPARE_RETRY_S = 2.0
"""After a spare failed, the next is started this long later (doubling per failure in a row, up to 60 s)."""
MAX_RETRY_S = 60.0


class SpareKeeper:
    """The spare of ``link``: :meth:`check` every supervision pass, :meth:`snapshot` for the status."""

    def __init__(self, link: TickLink) -> None:
        self.link = link
        self.failures = 0
        """Spares in a row that failed or died."""
        self.next_at = 0.0
        """Not before this (perf_counter s): a new serving generation's first beat, or the retry."""

    def check(self, now: float, serving: bool) -> None:
        """One look, when ``serving`` (up, no failover under way): start a spare if none, replace a failed one."""
        link = self.link
        if not serving or not link.spares_wanted or now < self.next_at:
            return
        spare = link.spare
        if spare is not None:
            spare.poll()
            if spare.failed is None and spare.process.is_alive():
                if spare.warm is not None:
                    self.failures = 0
                return
            reason = spare.failed or f"exited ({exit_reason(spare.process.exitcode)}, pid {spare.process.pid})"
            log.error("the spare tick %s: starting another", reason)
            self.failures += 1
            link.spares_failed += 1
            spare.discard()
            link.spare = None
            self.next_at = now + min(SPARE_RETRY_S * 2 ** (self.failures - 1), MAX_RETRY_S)
            return
        link.start_spare()

    def warm(self) -> bool:
        """A spare is warm, or none is wanted in a tick thread; never with ``tick.spare`` off
        (a failover is a cold start then, and the hang threshold says so)."""
        spare = self.link.spare
        if not self.link.spares_wanted:
            return not self.link.cold_failover
        return spare is not None and spare.warm is not None

    def snapshot(self) -> dict[str, Any]:
        link, spare = self.link, self.link.spare
        state = "none" if spare is None else "warm" if spare.warm is not None else "warming"
        return {
            "state": "off" if link.cold_failover else state,
            "pid": None if spare is None else spare.process.pid,
            "warm_up_s": None if spare is None or spare.warm is None else spare.warm.wall_s,
            "started": link.spares_started,
            "failed": link.spares_failed,
        }
