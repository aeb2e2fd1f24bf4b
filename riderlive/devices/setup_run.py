"""A plug's setup run a slice per tick, with its bound and its wait for a busy transport.

:class:`~riderlive.devices.device.Device` starts one :class:`SetupRun` per connect, reset or
reconnect and advances it from the tick for half a tick at a time: each step of the plug's
``setup`` generator is one transaction (open, check, configure, outputs off). A transport
another process still holds (``PortBusy``: the guardian, a tool) starts the setup over at
the next tick, counted in ``port_busy``; the first connect after a failover waits, without
touching the transport, for the guardian to hand the dead generation's devices back
(:class:`Handback`); a setup longer than :data:`SETUP_TIMEOUT_S` closes
the transport and raises ``SetupTimeout`` (the device faults; a reset tries again).
Times are ``perf_counter`` seconds.
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass

from riderlive.devices.lifecycle import PortBusy, SetupTimeout
from riderlive.devices.plug import Plug

log = logging.getLogger("riderlive.devices")

SETUP_TIMEOUT_S = 15.0
"""Longest a device may stay ``connecting`` (a transport held by another process, a setup
that never ends): then a ``setup_timeout`` fault, counted; a reset tries again. The
guardian's own wait for a port held by a process it has killed is shorter (5 s)."""


Gate = Callable[[], "str | None"]
"""Why the transport must not be opened yet (``devices.guardians.handback_pending``), None once it may."""


@dataclass(frozen=True)
class Handback:
    """A first connect after a failover: ``pending`` says why the guardian still holds the
    devices (None once handed back); waited for at most ``bound_s`` seconds."""

    pending: Gate
    bound_s: float


class HandbackTimeout(SetupTimeout):
    """The guardian did not hand the devices back within the bound (a ``setup_timeout`` fault)."""


class SetupRun:
    """One run of ``plug.setup``; ``say`` gets each step's detail (the device's status).

    With ``handback``, the transport is not touched until ``handback.pending()`` is None:
    the device stays ``connecting`` with the guardian's reason as its detail (counted once
    in ``handback_waits``); past ``handback.bound_s`` it raises ``HandbackTimeout`` (the
    device faults ``setup_timeout``, counted in ``handback_timeouts``; the device drops its
    hand-back then, so a reset connects without waiting).
    ``SETUP_TIMEOUT_S`` counts from the hand-back."""

    def __init__(
        self, plug: Plug, say: Callable[[str], None], counters: Counter[str], handback: Handback | None = None
    ) -> None:
        self._plug, self._say, self._counters = plug, say, counters
        self._handback = handback
        self._waited = False
        self.detail = ""
        self.since = time.perf_counter()
        self._steps = plug.setup(self._tell)  # a generator: nothing runs before the first step
        if handback is None or not self._wait_for_handback(self.since):
            self._tell("opening the transport")

    @property
    def waiting(self) -> bool:
        """Waiting for the guardian's hand-back: the transport is not ours (publish nothing of it)."""
        return self._handback is not None

    def _wait_for_handback(self, now: float) -> bool:
        """True while the guardian holds the devices (see the class docstring)."""
        handback = self._handback
        assert handback is not None
        why = handback.pending()
        if why is None:
            self._handback = None
            self.since = now
            return False
        if now - self.since > handback.bound_s:
            self._handback = None
            self._counters["handback_timeouts"] += 1
            raise HandbackTimeout(
                f"not connected: {why} for {now - self.since:.1f} s (bound {handback.bound_s:g} s); "
                "the transport was not touched (a reset connects)"
            )
        if not self._waited:
            self._waited = True
            self._counters["handback_waits"] += 1
        if why != self.detail:
            self._tell(why)
        return True

    def _tell(self, detail: str) -> None:
        self.detail = detail
        self._say(detail)

    def advance(self, budget_s: float) -> bool:
        """Setup transactions until ``budget_s`` is used; True once the setup has ended."""
        if self._handback is not None:
            if self._wait_for_handback(time.perf_counter()):
                return False
            self._tell("opening the transport")
        if (took := time.perf_counter() - self.since) > SETUP_TIMEOUT_S:
            try:
                self._plug.close()
            except Exception as exc:
                log.warning("%s: best-effort call failed: %s", self._plug.name, exc)
            raise SetupTimeout(f"still connecting after {took:.1f} s (bound {SETUP_TIMEOUT_S:g} s): {self.detail}")
        budget_end = time.perf_counter() + budget_s
        while True:
            try:
                next(self._steps)
            except StopIteration:
                return True
            except PortBusy as exc:  # the guardian (or another tool) still has the bus
                self._counters["port_busy"] += 1
                self._tell(f"waiting for the transport: {exc}")
                self._steps = self._plug.setup(self._tell)
                return False
            if time.perf_counter() >= budget_end:
                return False
