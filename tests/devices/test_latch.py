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


def test_a_request_waits_for_a_goal_write_in_progress(latch: StopLatch, monkeypatch: pytest.MonkeyPatch) -> None:
    """Either the whole write goes before the request, or the write is refused. (The
    requester's patience is raised here: a loaded machine may deschedule the writer for
    longer than the real 2 ms, which the next test covers.)"""
    monkeypatch.setattr(latch_module, "LOCK_WAIT_S", 5.0)
    view = latch.view()
    inside, done = threading.Event(), threading.Event()
    left_at: list[float] = []

    def writer() -> None:
        with view.gate():
            inside.set()
            time.sleep(0.001)  # a write system call, shorter than the requester's patience
            left_at.append(time.perf_counter())
        done.set()

    thread = threading.Thread(target=writer)
    thread.start()
    inside.wait(5)
    requested_at = latch.request(StopSource.API)
    thread.join()
    assert requested_at >= left_at[0]
    assert latch.lock_timeouts == 0


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


def test_a_signal_cannot_land_between_the_check_and_the_write(latch: StopLatch) -> None:
    """SIGTERM of the process that writes (its own handler asks for the e-stop): the
    request is recorded once the write in progress is done, never inside it."""
    view = latch.view()
    handled: list[float] = []

    def on_stop(signum: int, frame: object) -> None:
        handled.append(time.perf_counter())
        latch.request(StopSource.SIGNAL)

    previous = signal.signal(signal.SIGTERM, on_stop)
    try:
        with view.gate():
            os.kill(os.getpid(), signal.SIGTERM)
            deadline = time.perf_counter() + 5
            while not handled and time.perf_counter() < deadline:
                time.sleep(0.001)  # the handler runs here, inside the write
            assert handled and not view.pending  # asked, but not recorded yet
            written = time.perf_counter()
        assert view.pending and latch.source is StopSource.SIGNAL
        assert latch.requested_at >= written
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
