"""The guardian process and its standby, as the web process keeps them (``devices/guardian.py``).

The guardian parks and releases the devices of a tick generation that died or hung; it
lives outside the tick so that it survives it. A **standby** guardian (imports paid,
plugs built) becomes the guardian within a few ms of its death: a relaunch would cost a
Python start and the imports. :class:`Guardians` launches both, relaunches what died
(at most one launch a second), reports their state and waits, at a failover, until the
guardian has stopped the dead generation's devices.
"""

from __future__ import annotations

import asyncio
import logging
import subprocess
import time
from typing import Any

from riderlive.devices.board import SafetyBoard, guardian_watching
from riderlive.devices.guardian import launch
from riderlive.realtime.setup import TickSetup
from riderlive.service.config import ServiceConfig

log = logging.getLogger("riderlive.service.supervisor")
START_S = 5.0
"""Allowance for a guardian relaunched during a stop to start and finish it (its imports
on a loaded host), on top of the park timeout."""
RELAUNCH_S = 1.0
"""At most one launch this often (s)."""


class Guardians:
    """The guardian and its standby for the devices of ``setup``, on ``board`` (see the module docstring)."""

    def __init__(self, board: SafetyBoard, latch_name: str, setup: TickSetup, config: ServiceConfig) -> None:
        self.board = board
        self.latch_name = latch_name
        self.setup = setup
        self.config = config
        self.guardian: subprocess.Popen[bytes] | None = None
        self.standby: subprocess.Popen[bytes] | None = None
        """A standby guardian: becomes the guardian the moment it is gone (guardian.py)."""
        self.restarts = 0
        self._launched_at = 0.0

    def _launch(self, standby_after: int = 0) -> subprocess.Popen[bytes]:
        guardian = self.config.guardian
        return launch(
            self.board.name,
            self.latch_name,
            self.setup.devices,
            guardian.tick_timeout,
            guardian.web_timeout,
            give_up_s=guardian.give_up,
            standby_after=standby_after,
            priority=guardian.priority,
        )

    def start(self) -> None:
        """The guardian, and a standby watching it."""
        self.guardian = self._launch()
        self._launched_at = time.perf_counter()
        self.standby = self._launch(standby_after=self.guardian.pid)

    def check(self, now: float) -> None:
        """The guardian gone: its standby has taken over (or it is relaunched); a new standby
        follows (at most one launch a second)."""
        if self.guardian is None:
            return
        if self.guardian.poll() is not None:
            code = self.guardian.returncode
            if self.standby is not None and self.standby.poll() is None:
                log.critical("the guardian exited (%s): its standby %d takes over", code, self.standby.pid)
                self.guardian, self.standby = self.standby, None
            elif now - self._launched_at >= RELAUNCH_S:
                log.critical("the guardian exited (%s), no standby: relaunching it; arming is refused", code)
                self.board["guardian_ready"] = 0.0
                self.guardian, self.standby = self._launch(), None
                self._launched_at = now
            else:
                return
            self.restarts += 1
        if (self.standby is None or self.standby.poll() is not None) and now - self._launched_at >= RELAUNCH_S:
            self.standby = self._launch(standby_after=self.guardian.pid)
            self._launched_at = now

    def alive(self) -> bool:
        """Ready, its process alive, its heartbeat fresh (the tick's own test: board.guardian_watching)."""
        return self.guardian is not None and guardian_watching(self.board, time.perf_counter()) is None

    async def wait_for_stop(self, generation: int) -> None:
        """Until the guardian has stopped that generation's devices (bounded)."""
        if self.guardian is None:
            return
        deadline = time.perf_counter() + self.config.rig.park_timeout + 3.0 + START_S
        while time.perf_counter() < deadline:  # a guardian that dies meanwhile is relaunched and goes on
            if self.board["guardian_done"] >= generation:
                return
            await asyncio.sleep(0.01)
        log.error("the guardian did not report the stop of generation %d in time", generation)

    def stop(self) -> None:
        """After the tick has stopped (its devices are closed): the guardian may go."""
        self.board["shutdown"] = 1.0
        for guardian in (self.guardian, self.standby):
            if guardian is not None:
                try:
                    guardian.wait(2.0)
                except subprocess.TimeoutExpired:
                    guardian.kill()
                    guardian.wait(2.0)

    def snapshot(self, enabled: bool) -> dict[str, Any]:
        guardian, standby = self.guardian, self.standby
        return {
            "enabled": enabled,
            "alive": self.alive(),
            "pid": None if guardian is None else guardian.pid,
            "standby_pid": None if standby is None or standby.poll() is not None else standby.pid,
            "standby_ready": standby is not None and self.board["guardian_standby"] == standby.pid,
            "restarts": self.restarts,
            "takeovers": int(self.board["guardian_takeovers"]),
        }
