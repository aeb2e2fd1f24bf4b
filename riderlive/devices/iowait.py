"""The tick's declaration "waiting on device I/O until D", for the supervisor's hang judgement.

A bus transaction waits for a servo's reply asleep in ``select``, bounded by its reply
timeout; on a busy host the reply's bytes can come late (the kernel's tty worker runs at
normal priority), and a tick that waits out a few such bounded waits in one tick can beat
later than the hang threshold without being stuck. So before each wait the bus declares
its deadline on the safety board (``SafetyBoard.tick_io_until``: one aligned 8-byte store,
``devices/shared.py``) and clears it when the transaction ends; the supervisor excuses a
late heartbeat only inside that declared, bounded wait (``service/stall.py``).

Cost: one slot store per wait and per transaction end (~0.1 us each; docs/performance.md).
Only the tick declares: the guardian's plugs have no :class:`IoWait` (``None``).
"""

from __future__ import annotations

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
    """:class:`IoWait` on the safety board's ``tick_io_until`` slot."""

    def __init__(self, board: SafetyBoard) -> None:
        self.board = board

    def until(self, deadline: float) -> None:
        """A wait for bytes begins; it ends by ``deadline`` (perf_counter s)."""
        self.board.tick_io_until = deadline

    def done(self) -> None:
        """The transaction ended (a reply, a timeout, an error)."""
        self.board.tick_io_until = 0.0
