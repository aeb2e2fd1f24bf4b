"""Waiting in tests on events, not on the clock.

- :class:`Inbox`: a list that threads append to and tests wait on (a condition variable:
  the waiter wakes on each append, no polling).
- :func:`wait_until` (and :func:`await_until` in a coroutine): poll a condition, for what
  has no event to wait on (a server's REST state, another process's files, shared memory).
- :class:`Pacer`: a loop's rate on deadlines (a producer, a tick), not a wait.

The sleeps here are the only waiting or pacing sleeps of the tests (``tests/test_sleeps.py``).
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Callable, Iterator
from typing import Generic, TypeVar

T = TypeVar("T")
POLL_S = 0.01


def _polls(
    condition: Callable[[], object], timeout: float, what: Callable[[], object] | str, poll: float
) -> Iterator[float]:
    """The one poll loop of :func:`wait_until` and :func:`await_until`: yields the delay to sleep
    (s) while ``condition()`` is false; AssertionError naming ``what`` after ``timeout`` s."""
    deadline = time.perf_counter() + timeout
    while not condition():
        if time.perf_counter() > deadline:
            said = what() if callable(what) else what
            raise AssertionError(f"timed out after {timeout} s: {said}")
        yield poll


def wait_until(
    condition: Callable[[], object], timeout: float, what: Callable[[], object] | str = "", poll: float = POLL_S
) -> None:
    """Return once ``condition()`` is true; AssertionError naming ``what`` after ``timeout`` s."""
    for delay in _polls(condition, timeout, what, poll):
        time.sleep(delay)


async def await_until(
    condition: Callable[[], object], timeout: float, what: Callable[[], object] | str = "", poll: float = POLL_S
) -> None:
    """:func:`wait_until` in a coroutine (the loop runs meanwhile)."""
    for delay in _polls(condition, timeout, what, poll):
        await asyncio.sleep(delay)


class Pacer:
    """One pass every ``period`` s on deadlines from the first :meth:`wait`: a late pass is not
    made up (the next deadline is a period after it), so the rate never bursts."""

    def __init__(self, period: float) -> None:
        self.period = period
        self.next: float | None = None

    def _delay(self) -> float:
        now = time.perf_counter()
        self.next = (now if self.next is None else max(self.next, now - self.period)) + self.period
        return max(0.0, self.next - now)

    def wait(self) -> None:
        """Sleep until the next deadline."""
        time.sleep(self._delay())

    async def await_next(self) -> None:
        """:meth:`wait` in a coroutine."""
        await asyncio.sleep(self._delay())


class Inbox(Generic[T]):
    """Items appended by one thread, awaited by another."""

    def __init__(self) -> None:
        self.items: list[T] = []
        self._changed = threading.Condition()

    def append(self, item: T) -> None:
        with self._changed:
            self.items.append(item)
            self._changed.notify_all()

    def __len__(self) -> int:
        return len(self.items)

    def wait_for(self, predicate: Callable[[T], bool], timeout: float, start: int = 0) -> T:
        """The first item from index ``start`` on that matches, waiting for it up to ``timeout`` s."""
        deadline = time.perf_counter() + timeout
        seen = start
        with self._changed:
            while True:
                for item in self.items[seen:]:
                    if predicate(item):
                        return item
                seen = len(self.items)
                left = deadline - time.perf_counter()
                if left <= 0 or not self._changed.wait(left):
                    last = self.items[-1] if self.items else None
                    raise AssertionError(f"nothing matched within {timeout} s; last: {last}")

    def wait_count(self, predicate: Callable[[T], bool], count: int, timeout: float, start: int = 0) -> list[T]:
        """``count`` items from index ``start`` on that match, waiting for them up to ``timeout`` s."""
        deadline = time.perf_counter() + timeout
        with self._changed:
            while True:
                found = [item for item in self.items[start:] if predicate(item)]
                if len(found) >= count:
                    return found
                left = deadline - time.perf_counter()
                if left <= 0 or not self._changed.wait(left):
                    raise AssertionError(f"{len(found)} of {count} items within {timeout} s")
