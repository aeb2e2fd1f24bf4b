"""The e-stop latch shared by every process that may ask for or act on an e-stop.

An e-stop is a *request* (any thread, any process, a signal handler: the web process
for REST and websocket e-stops, the CLI on SIGINT/SIGTERM) and a *reaction* (the
process that owns the bus writes torque off). Between the two lives this latch: a few
slots in shared memory and a file lock on that segment.

"No goal write begins after the request" is structural. A request is recorded at once
(its first act is the one store to shared memory that writers check, its time is read
after that store; no lock, nothing to wait for: from a signal handler too), and every
goal write happens inside :meth:`StopView.gate`, which refuses
(:class:`StopRequested`) when a request is pending at its entry **and again at the
write itself** (:meth:`StopView.check_write`, called by the transport immediately
before the bytes go out, under the gate's lock): a request recorded while the writer
computed, drained the line or was descheduled stops the write it was about to send.
After recording, :meth:`StopLatch.request` takes the gate's lock (a file lock on the
segment) so that it returns only once a write already under way has left: from then
on no goal can be in progress. The lock is held for one write system call (~20 us); a
requester that cannot get it within ``LOCK_WAIT_S`` (the writer is frozen, say)
returns anyway and counts it. A killed holder releases the lock with its file.

The latch stays set until :meth:`clear` (an operator's reset), across tick restarts:
new devices that find it set go to ``estop``, not ``disarmed``.
"""

from __future__ import annotations

import contextlib
import enum
import fcntl
import os
import threading
import time
from collections.abc import Iterator

from riderlive.devices.lifecycle import StopRequested
from riderlive.devices.shared import Slot, SlotBlock, Slots, lock_path

LOCK_WAIT_S = 0.002
"""How long a request (already recorded) waits for a goal write under way to leave."""


class StopSource(enum.IntEnum):
    """Where an e-stop came from (stored as a number in shared memory)."""

    API = 1
    REST = 2
    WEBSOCKET = 3
    SIGNAL = 4
    GUARDIAN = 5
    NATS = 6
    """The stage e-stop or a control request over NATS (riderlive.bus)."""

    @property
    def label(self) -> str:
        return self.name.lower()


_ANY = "any process that asks for an e-stop"


class _LatchSlots(Slots, SlotBlock):
    """The latch's segment: typed slots, read and written by attribute."""

    requested = Slot(int, _ANY, "e-stop requests so far (the one store every gate and write checks)")
    latched = Slot(float, f"{_ANY}; cleared by an operator's reset", "1 from a request until a reset")
    requested_at = Slot(float, _ANY, "perf_counter s of the last request (read after its store)")
    source = Slot(int, _ANY, "the last request's StopSource")
    lock_timeouts = Slot(int, _ANY, "requests that did not get the gate's lock within LOCK_WAIT_S")

    def __init__(self, name: str | None = None) -> None:
        super().__init__(self.slot_names(), name)


class StopLatch:
    """The latch; ``StopLatch()`` creates one, ``StopLatch(name)`` attaches to it."""

    def __init__(self, name: str | None = None) -> None:
        self._slots = _LatchSlots(name)
        path = str(lock_path(self._slots.name))
        self._gate_fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)
        self._request_fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)
        self._thread_lock = threading.Lock()  # requests from threads of one process: one at a time
        self._gate_owner: int | None = None
        """The thread inside a gate of this process (a signal handler may interrupt it)."""

    @property
    def name(self) -> str:
        return self._slots.name

    # -- the requester's side ----------------------------------------------------------

    def request(self, source: StopSource = StopSource.API) -> float:
        """Record an e-stop request at once; return its time (perf_counter s, taken right
        after the record: every goal write stamped later than it is refused).

        The first act is the one store that every gate and every at-write check reads
        (``requested``); the time is read after it. A writer stamps its write's beginning
        before its check (:meth:`StopView.check_write`), so a write whose beginning is
        later than the returned time checked after the store and was refused: there is no
        instant at which the request has a time but is not yet visible to a writer.

        Then wait (up to ``LOCK_WAIT_S``) for a goal write under way to leave, unless the
        caller is a signal handler that interrupted this thread's own write (the write's
        check refuses it if it has not begun). Two requests at the same instant from two
        processes may count as one in ``requested`` (both latch, and both are pending)."""
        slots = self._slots
        slots.requested = slots.requested + 1  # first: pending from here, every gate and write refuses
        now = time.perf_counter()  # after the store: nothing stamped later can pass a check
        slots.latched = 1.0  # (a gate refuses on `requested`; `latched` is for reset and new devices)
        slots.requested_at = now
        slots.source = int(source)
        if self._gate_owner == threading.get_ident():
            return now
        acquired = self._thread_lock.acquire(timeout=LOCK_WAIT_S)
        try:
            if self._flock(self._request_fd, LOCK_WAIT_S):
                fcntl.flock(self._request_fd, fcntl.LOCK_UN)
            else:
                slots.lock_timeouts = slots.lock_timeouts + 1
        finally:
            if acquired:
                self._thread_lock.release()
        return now

    @staticmethod
    def _flock(fd: int, wait_s: float) -> bool:
        deadline = time.perf_counter() + wait_s
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                return True
            except BlockingIOError:
                if time.perf_counter() >= deadline:
                    return False
                time.sleep(0.00002)

    # -- the reacting side -------------------------------------------------------------

    @property
    def requested(self) -> int:
        """E-stop requests so far (each device remembers how many it has acted on)."""
        return self._slots.requested

    @property
    def latched(self) -> bool:
        """An e-stop was requested and no reset has cleared it since."""
        return self._slots.latched != 0.0

    @property
    def requested_at(self) -> float:
        return self._slots.requested_at

    @property
    def source(self) -> StopSource | None:
        code = self._slots.source
        return StopSource(code) if code in StopSource._value2member_map_ else None

    @property
    def lock_timeouts(self) -> int:
        return self._slots.lock_timeouts

    def view(self) -> StopView:
        """One writer's view: which requests it has acted on, and its goal-write gate."""
        return StopView(self)

    def clear(self) -> None:
        """An operator's reset: unlatch (requests already made stay counted)."""
        self._slots.latched = 0.0

    def close(self) -> None:
        for fd in (self._gate_fd, self._request_fd):
            with contextlib.suppress(OSError):
                os.close(fd)
        self._slots.close()


class StopView:
    """A writer's side of the latch: ``pending`` means a request it has not acted on."""

    def __init__(self, latch: StopLatch) -> None:
        self.latch = latch
        self.seen = latch.requested
        """Requests already acted on (a new view ignores requests made before it existed;
        a latched latch is the devices' business: they start in ``estop``)."""

    @property
    def pending(self) -> bool:
        return self.latch.requested > self.seen

    def take(self) -> bool:
        """Mark every request so far as acted on; True if there was a new one."""
        requested = self.latch.requested
        if requested <= self.seen:
            return False
        self.seen = requested
        return True

    def check_write(self) -> None:
        """Immediately before a write's bytes go out: inside this thread's gate, raise
        StopRequested if a request was recorded since the gate's entry (outside a gate:
        nothing to check, an outputs-off or a read). The caller stamps the write's
        beginning *before* calling this (see :meth:`StopLatch.request`: a write stamped
        after a request's time is then always refused)."""
        if self.latch._gate_owner == threading.get_ident() and self.pending:
            raise StopRequested("e-stop requested before the write began")

    @contextlib.contextmanager
    def gate(self) -> Iterator[None]:
        """Around a goal write: raises StopRequested instead of entering if a request is
        pending; the transport calls :meth:`check_write` at the write itself."""
        latch = self.latch
        if not latch._flock(latch._gate_fd, LOCK_WAIT_S):
            raise StopRequested("e-stop being requested")
        latch._gate_owner = threading.get_ident()
        try:
            if self.pending:
                raise StopRequested("e-stop requested")
            yield
        finally:
            latch._gate_owner = None
            fcntl.flock(latch._gate_fd, fcntl.LOCK_UN)
