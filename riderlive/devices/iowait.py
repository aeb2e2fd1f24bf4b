"""The tick's declaration "waiting on device I/O until D", for the supervisor's hang judgement.

A bus transaction waits for a servo's reply asleep in ``select``, bounded by its reply
timeout; on a busy host the reply's bytes can come late (the kernel's tty worker runs at
normal priority), and a tick that waits out a few such bounded waits in one tick can beat
later than the hang threshold without being stuck. So before each wait the bus declares
its deadline on the safety board (``SafetyBoard.tick_io_until``: one aligned 8-byte store,
``devices/shared.py``) and clears it when the transaction ends; the supervisor excuses a
late heartbeat only inside that declared, bounded wait (``service/stall.py``).

Cost: a few slot stores per transaction (docs/performance.md, "Stalls (issue 24)").
Only the tick declares: the guardian's plugs have no :class:`IoWait` (``None``).
"""

from __future__ import annotations

import time
from typing import Protocol, runtime_checkable

from riderlive.devices.board import SafetyBoard


class IoWait(Protocol):
    """Where a bus declares its waits (seconds on ``time.perf_counter``)."""

    def until(self, deadline: float) -> None: ...
    def done(self) -> None: ...


@runtime_checkable
class DeclaresIoWaits(Protocol):
    """A plug whose bus declares its waits (the Dynamixel rig's)."""

    io_wait: IoWait | None


class BoardIoWait:
    """:class:`IoWait` on the safety board: ``tick_io_since`` / ``tick_io_until`` while a wait
    lasts, then its length added to ``tick_io_waited`` (the tick zeroes that at each beat:
    :meth:`beat`). Only the time up to each wait's deadline is added."""

    def __init__(self, board: SafetyBoard) -> None:
        self.board = board
        self._since = 0.0
        self._until = 0.0

    def until(self, deadline: float) -> None:
        """A wait for bytes begins now; it ends by ``deadline`` (perf_counter s)."""
        now = time.perf_counter()
        if self._until:
            self._end(now)
        board = self.board
        self._since, self._until = now, deadline
        board.tick_io_since = now
        board.tick_io_until = deadline

    def done(self) -> None:
        """The transaction ended (a reply, a timeout, an error)."""
        if self._until:
            self._end(time.perf_counter())
            self.board.tick_io_until = 0.0

    def _end(self, now: float) -> None:
        board = self.board
        board.tick_io_waited = board.tick_io_waited + max(0.0, min(now, self._until) - self._since)
        self._until = 0.0


def beat(board: SafetyBoard, now: float) -> None:
    """The tick's heartbeat (perf_counter s): a new gap, with no device wait in it yet."""
    board.tick_beat = now
    board.tick_io_waited = 0.0
