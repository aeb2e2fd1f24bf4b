"""Telling a transient miss from a real failure: reply timeouts and error budgets.

- :class:`ReplyTimer`: how long to wait for a reply, from measured round trips with a
  margin (the estimator of TCP's retransmission timer, Jacobson/Karels 1988): the
  timeout follows the machine's real scheduling delays instead of a fixed few
  milliseconds that a loaded host overruns, and backs off after a miss.
- :class:`ErrorBudget`: a bucket per transport. Each failure adds one, each success
  takes one out: the budget is spent only when failures outnumber successes for long
  enough (persistent corruption), never by scattered misses, however many over time
  (a loaded host misses now and then; a broken bus misses always).

Per-unit silence (a servo that stopped answering) is a time budget kept by the plug:
retried every tick, faulted only after ``reply_budget_s`` without one answer. Pure
arithmetic; times in seconds unless the name says milliseconds.
"""

from __future__ import annotations

from dataclasses import dataclass


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
    """A bucket of failures: each failure adds one, each success takes ``credit`` out (not
    below 0); the budget is spent when the bucket holds more than ``burst``. Failures
    that stay fewer than ``credit`` x the successes never spend it, however long; a
    transport that fails (nearly) every time spends it after ``burst`` failures."""

    burst: float = 20.0
    credit: float = 1.0
    level: float = 0.0
    failures: int = 0
    successes: int = 0

    def fail(self) -> bool:
        """Count one failure; True when the budget is spent."""
        self.level += 1.0
        self.failures += 1
        return self.level > self.burst

    def ok(self) -> None:
        self.level = max(0.0, self.level - self.credit)
        self.successes += 1

    def reset(self) -> None:
        self.level = 0.0

    def failures_to_spend(self, failure_ratio: float) -> float:
        """How many failures at this share of attempts spend a full budget (inf if never)."""
        net = failure_ratio - (1.0 - failure_ratio) * self.credit
        return float("inf") if net <= 0 else self.burst / net * failure_ratio
