"""The tick's edge of the phase lock: the pure unit (:mod:`riderlive.realtime.phase_lock`)
stepped with the frames the tick took, the deadline clock moved, the counters written.

The tick calls :meth:`PhaseFollower.follow` once per tick, after its output is out (never
on the latency path), with the receive times (engine seconds) of the horse frames it took
from the driving producer, or producer -1 when no horse input drives (a saddle input, the
procedural horse, nothing): then the clock is left as it is.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from riderlive.realtime import phase_lock as phase
from riderlive.realtime.pacing import DeadlineClock

if TYPE_CHECKING:
    from riderlive.realtime.counters import TickCounters


class PhaseFollower:
    """The lock's model (None: off) and state; :meth:`start` with the clock's origin."""

    def __init__(self, rate: float, margin: float, enabled: bool = True) -> None:
        self.model = phase.Model(1.0 / rate, margin) if enabled else None
        self.state = phase.State()

    @property
    def enabled(self) -> bool:
        return self.model is not None

    def start(self, origin: float) -> None:
        """Deadlines at ``origin + n * period`` (engine seconds), nothing learnt yet."""
        self.state = phase.start(origin)

    def follow(
        self,
        clock: DeadlineClock,
        now: float,
        producer: int,
        arrivals: list[float],
        counter: TickCounters,
    ) -> bool:
        """One tick at engine time ``now``: step the lock, move ``clock``, write the ``phase_*``
        counters; True when the lock was taken or let go."""
        assert self.model is not None
        was = self.state.locked
        self.state = s = phase.step(self.model, self.state, now, producer, arrivals)
        clock.start += s.shift  # |shift| <= slew * period: the next deadline is that much nearer or later
        lead = phase.lead(self.model, s)
        counter.phase_locked = float(s.locked)
        counter.phase_lead = lead if math.isfinite(lead) else -1.0
        counter.phase_margin = s.margin if math.isfinite(s.margin) else -1.0
        counter.phase_resultant = s.resultant
        counter.phase_slews = s.slews
        counter.phase_locks = s.locks
        counter.phase_losses = s.losses
        return s.locked is not was

    def status(self) -> dict[str, Any] | None:
        """The lock as of its last lock or loss (None when off); the live lead, margin and slews
        are counters (``/metrics``, ``/api/latency``)."""
        if self.model is None:
            return None
        s = self.state
        return {
            "locked": s.locked,
            "harmonic": s.harmonic,
            "resultant": s.resultant,
            "spread": None if math.isnan(s.spread) else s.spread,
            "drift": s.drift,
            "locks": s.locks,
            "losses": s.losses,
            "lost": s.lost or None,
        }
