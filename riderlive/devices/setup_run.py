"""A plug's setup run a slice per tick, with its bound and its wait for a busy transport.

:class:`~riderlive.devices.device.Device` starts one :class:`SetupRun` per connect, reset or
reconnect and advances it from the tick for half a tick at a time: each step of the plug's
``setup`` generator is one transaction (open, check, configure, outputs off). A transport
another process still holds (``PortBusy``: the guardian, a tool) starts the setup over at
the next tick, counted in ``port_busy``; a setup longer than :data:`SETUP_TIMEOUT_S` closes
the transport and raises ``SetupTimeout`` (the device faults; a reset tries again).
Times are ``perf_counter`` seconds.
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from collections.abc import Callable

from riderlive.devices.lifecycle import PortBusy, SetupTimeout
from riderlive.devices.plug import Plug

log = logging.getLogger("riderlive.devices")

SETUP_TIMEOUT_S = 15.0
"""Longest a device may stay ``connecting`` (a transport held by another process, a setup
that never ends): then a ``setup_timeout`` fault, counted; a reset tries again. The
guardian's own wait for a port held by a process it has killed is shorter (5 s)."""


class SetupRun:
    """One run of ``plug.setup``; ``say`` gets each step's detail (the device's status)."""

    def __init__(self, plug: Plug, say: Callable[[str], None], counters: Counter[str]) -> None:
        self._plug, self._say, self._counters = plug, say, counters
        self.detail = ""
        self._tell("opening the transport")
        self._steps = plug.setup(self._tell)
        self.since = time.perf_counter()

    def _tell(self, detail: str) -> None:
        self.detail = detail
        self._say(detail)

    def advance(self, budget_s: float) -> bool:
        """Setup transactions until ``budget_s`` is used; True once the setup has ended."""
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
