"""The e-stop latch across threads, processes and signals; the goal-write gate."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator

import pytest

from riderlive.devices import latch as latch_module
from riderlive.devices.latch import StopLatch, StopSource
from riderlive.devices.lifecycle import StopRequested
from tests.waiting import wait_until


@pytest.fixture
def latch() -> Iterator[StopLatch]:
    shared = StopLatch()
    yield shared
    shared.close()


def run_python(code: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)


def test_a_request_from_another_process_is_seen_and_latched(latch: StopLatch) -> None:
    view = latch.view()
    assert not view.pending and not latch.latched
    child = run_python(
        f"from riderlive.devices.latch import StopLatch, StopSource\n"
        f"latch = StopLatch({latch.name!r}); print(latch.request(StopSource.REST)); latch.close()"
    )
    out, _ = child.communicate(timeout=30)
    requested_at = float(out.strip())
    assert view.pending and latch.latched
    assert latch.requested_at == requested_at and latch.source is StopSource.REST
    with pytest.raises(StopRequested), view.gate():
        pass  # never entered
    assert view.take() and not view.pending and not view.take()
    with view.gate():
        pass  # acted on: goals may go out again (the device decides, it is in estop)
    assert latch.latched  # until an operator's reset
    latch.clear()
    assert not latch.latched and latch.requested == 1


def test_a_request_is_recorded_at_once_and_returns_after_the_write_under_way(
    latch: StopLatch, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The latch is set before anything waits; request() returns only once the write that
    had begun has left. (The requester's patience is raised here: a loaded machine may
    deschedule the writer for longer than the real 2 ms, which a test below covers.)"""
    monkeypatch.setattr(latch_module, "LOCK_WAIT_S", 5.0)
    view = latch.view()
    began, done = threading.Event(), threading.Event()
    left_at: list[float] = []

    def writer() -> None:
        with view.gate():
            view.check_write()  # the write's bytes go out from here
            began.set()
            # a write system call, which the request arrives during (however the host schedules us)
            wait_until(lambda: view.pending, 5.0, "the request", poll=0.0002)
            left_at.append(time.perf_counter())
        done.set()

    thread = threading.Thread(target=writer)
    thread.start()
    began.wait(5)
    requested_at = latch.request(StopSource.API)
    returned_at = time.perf_counter()
    thread.join()
    assert requested_at < left_at[0] <= returned_at  # latched at once, returned after the write
    assert latch.latched and view.pending and latch.lock_timeouts == 0


def test_a_write_that_has_not_begun_when_the_request_is_recorded_is_refused(latch: StopLatch) -> None:
    """The gate was entered before the request (the check passed), the write had not
    begun (the writer computed, drained the line, was descheduled): refused at the write."""
    view = latch.view()
    entered, outcome = threading.Event(), []

    def writer() -> None:
        try:
            with view.gate():
                entered.set()
                wait_until(lambda: latch.requested != 0, 5.0, "the request", poll=0.0001)
                view.check_write()
                outcome.append("written")
        except StopRequested:
            outcome.append("refused")

    thread = threading.Thread(target=writer)
    thread.start()
    entered.wait(5)
    latch.request(StopSource.REST)
    thread.join()
    assert outcome == ["refused"]
    with pytest.raises(StopRequested), view.gate():
        pass  # and no later gate opens until the request is acted on
    view.check_write()  # outside a gate (an outputs-off, a read): nothing to refuse


def test_a_writer_that_holds_the_gate_too_long_cannot_block_the_request(latch: StopLatch) -> None:
    view = latch.view()
    inside, release = threading.Event(), threading.Event()

    def stuck_writer() -> None:
        with view.gate():
            inside.set()
            release.wait(5)

    thread = threading.Thread(target=stuck_writer)
    thread.start()
    inside.wait(5)
    started = time.perf_counter()
    latch.request(StopSource.API)
    assert time.perf_counter() - started < 0.05
    assert latch.lock_timeouts == 1 and view.pending
    release.set()
    thread.join()


def test_a_signal_inside_the_gate_is_recorded_at_once_and_stops_the_write(latch: StopLatch) -> None:
    """SIGTERM of the process that writes (its own handler asks for the e-stop) between
    the gate's check and the write: recorded at once (no wait on its own lock), and the
    write that had not begun is refused."""
    view = latch.view()
    handled: list[float] = []

    def on_stop(signum: int, frame: object) -> None:
        handled.append(latch.request(StopSource.SIGNAL))

    previous = signal.signal(signal.SIGTERM, on_stop)
    try:
        with pytest.raises(StopRequested), view.gate():
            os.kill(os.getpid(), signal.SIGTERM)
            wait_until(lambda: handled, 5.0, "the handler", poll=0.001)  # it runs here, inside the gate
            assert handled and view.pending and latch.source is StopSource.SIGNAL
            view.check_write()
            pytest.fail("the write went out after the request")
        assert latch.requested_at == handled[0] and latch.lock_timeouts == 0
    finally:
        signal.signal(signal.SIGTERM, previous)


def test_a_killed_gate_holder_releases_the_lock(latch: StopLatch) -> None:
    child = run_python(
        f"import sys, time\nfrom riderlive.devices.latch import StopLatch\n"
        f"latch = StopLatch({latch.name!r}); view = latch.view()\n"
        f"with view.gate():\n    print('inside', flush=True); time.sleep(60)\n"
    )
    assert child.stdout is not None and child.stdout.readline().strip() == "inside"
    child.kill()
    child.wait(10)
    latch.request(StopSource.API)
    assert latch.lock_timeouts == 0


class _ClockThatHandsOver:
    """The latch module's ``time``: the requester's first clock read (its request's time)
    lets a writer run its check right then and waits until the writer has gone through
    it; every other read is the real clock. This is the worst instant for a request: a
    write that begins just after the request's time."""

    def __init__(self, requester: str, stamped: threading.Event, checked: threading.Event) -> None:
        self.requester, self.stamped, self.checked = requester, stamped, checked
        self.sleep = time.sleep

    def perf_counter(self) -> float:
        now = time.perf_counter()
        if threading.current_thread().name == self.requester and not self.stamped.is_set():
            self.stamped.set()
            assert self.checked.wait(5), "the writer never reached its check"
        return now


def test_a_write_stamped_after_the_request_s_time_is_refused(latch: StopLatch, monkeypatch: pytest.MonkeyPatch) -> None:
    """The request's time is read after its store (issue 25): a writer that stamps its
    write just after that time, then checks, is refused. With the time read before the
    store (the old order) the check ran before the store and the write went out."""
    view = latch.view()
    stamped, checked = threading.Event(), threading.Event()
    outcome: list[tuple[str, float]] = []
    requested: list[float] = []

    def requester() -> None:
        requested.append(latch.request(StopSource.REST))

    thread = threading.Thread(target=requester, name="requester")
    monkeypatch.setattr(latch_module, "time", _ClockThatHandsOver("requester", stamped, checked))
    with view.gate():  # entered before the request: the gate's own check passes
        thread.start()
        assert stamped.wait(5)
        begun = time.perf_counter()  # the write begins: stamped, then checked
        try:
            view.check_write()
            outcome.append(("written", begun))
        except StopRequested:
            outcome.append(("refused", begun))
        checked.set()
    thread.join(10)
    assert requested and outcome[0][1] > requested[0]  # began after the request's time
    assert outcome[0][0] == "refused"


def test_the_latch_s_slots_are_typed_each_naming_its_writer(latch: StopLatch) -> None:
    """The segment's slots by attribute (devices/shared.py's Slot), never by string key."""
    slots = latch_module._LatchSlots
    assert slots.slot_names() == ("requested", "latched", "requested_at", "source", "lock_timeouts")
    assert all(s.writer and s.doc for s in slots.slots())
    latch.request(StopSource.NATS)
    latch.request(StopSource.SIGNAL)
    assert latch.requested == 2 and type(latch.requested) is int and latch.source is StopSource.SIGNAL
    attached = StopLatch(latch.name)
    try:
        assert attached.requested == 2 and attached.latched and attached.requested_at == latch.requested_at
    finally:
        attached.close()
