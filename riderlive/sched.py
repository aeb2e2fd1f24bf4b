"""Scheduling of riderlive's processes and threads: SCHED_FIFO where the host permits it.

The priorities, highest first: the tick (50), the guardian and its standby (20, once their
imports are paid), the web process's event loop (10); everything else (the web process's
worker threads, bakes, the host's other work) at normal scheduling. A process that may not
use SCHED_FIFO (no root, no rtprio limit) runs at normal priority with a warning.
"""

from __future__ import annotations

import logging
import os

log = logging.getLogger(__name__)


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
