"""The tick's declared device waits on the safety board (devices/iowait.py)."""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest

from riderlive.devices import iowait
from riderlive.devices.board import SafetyBoard


@pytest.fixture
def board() -> Iterator[SafetyBoard]:
    b = SafetyBoard()
    yield b
    b.close()


def test_a_wait_is_declared_while_it_lasts_and_added_up_to_its_deadline(board: SafetyBoard) -> None:
    declare = iowait.BoardIoWait(board)
    seen = SafetyBoard(board.name)  # the supervisor's view
    try:
        iowait.beat(board, time.perf_counter())
        t0 = time.perf_counter()
        declare.until(t0 + 10.0)
        assert seen.tick_io_until == t0 + 10.0 and t0 <= seen.tick_io_since <= time.perf_counter()
        declare.done()
        ended = time.perf_counter()
        assert seen.tick_io_until == 0.0
        assert 0.0 <= seen.tick_io_waited <= ended - t0
        first = seen.tick_io_waited
        # A wait past its deadline adds only up to the deadline; a second until() ends the first.
        declare.until(time.perf_counter() - 1.0)
        declare.until(time.perf_counter() + 1.0)
        declare.done()
        declare.done()  # a transaction that never waited: nothing more
        assert seen.tick_io_waited - first <= time.perf_counter() - ended
        iowait.beat(board, time.perf_counter())
        assert seen.tick_io_waited == 0.0, "a beat starts a new gap"
    finally:
        seen.close()
