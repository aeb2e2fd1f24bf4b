"""Telling a transient miss from a real failure: reply timeouts and error budgets.

- :class:`ReplyTimer`: how long to wait for a reply, from measured round trips with a
  margin (the estimator of TCP's retransmission timer, Jacobson/Karels 1988): the
  timeout follows the machine's real scheduling delays instead of a fixed few
  milliseconds that a loaded host overruns, and backs off after a miss.
- :class:`ErrorBudget`: a leaky bucket per transport. Each failure adds one; the
  bucket drains at a steady rate; the budget is spent when failures come faster than
  they drain for long enough (persistent corruption), never by a scattered few.

Per-unit silence (a servo that stopped answering) is a time budget kept by the plug:
retried every tick, faulted only after ``reply_budget_s`` without one answer. Pure
arithmetic; times in seconds unless the name says milliseconds.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class ReplyTimer:
    """Reply timeout = expected wire time + the allowance for the host's delays.

    The allowance is ``srtt + 4 * rttvar`` of the measured *excess* (round trip minus
    the expected wire time), never below ``floor_ms``, doubled after each miss up to
    ``max_backoff`` times, and capped at ``ceiling_ms`` (or the floor, if higher).
    """

    floor_ms: float = 2.0
    ceiling_ms: float = 25.0
    max_backoff: int = 4
    srtt_ms: float | None = None
    rttvar_ms: float = 0.0
    backoff: int = 1
    samples: int = 0
    misses: int = 0

    def allowance_ms(self) -> float:
        """What is added to the wire time before a reply counts as missing."""
        if self.srtt_ms is None:
            base = 4.0 * self.floor_ms  # untrained: generous until the first replies
        else:
            base = max(self.floor_ms, self.srtt_ms + 4.0 * self.rttvar_ms)
        return min(base * self.backoff, max(self.ceiling_ms, self.floor_ms))

    def timeout_ms(self, expected_ms: float) -> float:
        return expected_ms + self.allowance_ms()

    def observe(self, excess_ms: float) -> None:
        """A reply came ``excess_ms`` after its expected wire time (clamped at 0)."""
        excess = max(excess_ms, 0.0)
        if self.srtt_ms is None:
            self.srtt_ms, self.rttvar_ms = excess, excess / 2.0
        else:
            self.rttvar_ms += 0.25 * (abs(self.srtt_ms - excess) - self.rttvar_ms)
            self.srtt_ms += 0.125 * (excess - self.srtt_ms)
        self.backoff = 1
        self.samples += 1

    def missed(self) -> None:
        """A reply did not come in time: wait longer next time (until one does)."""
        self.misses += 1
        self.backoff = min(self.backoff * 2, self.max_backoff)


@dataclass
class ErrorBudget:
    """A leaky bucket of failures: ``burst`` failures at once, ``drain_per_s`` sustained."""

    burst: float = 20.0
    drain_per_s: float = 5.0
    level: float = 0.0
    failures: int = 0
    _at: float | None = field(default=None, repr=False)

    def _drain(self, now: float) -> None:
        if self._at is not None:
            self.level = max(0.0, self.level - (now - self._at) * self.drain_per_s)
        self._at = now

    def fail(self, now: float) -> bool:
        """Count one failure at ``now``; True when the budget is spent."""
        self._drain(now)
        self.level += 1.0
        self.failures += 1
        return self.level > self.burst

    def current(self, now: float) -> float:
        self._drain(now)
        return self.level

    def reset(self) -> None:
        self.level = 0.0
        self._at = None

    def seconds_to_spend(self, failures_per_s: float) -> float:
        """How long failures arriving at this rate take to spend a full budget (inf if never)."""
        if failures_per_s <= self.drain_per_s:
            return float("inf")
        return self.burst / (failures_per_s - self.drain_per_s)
