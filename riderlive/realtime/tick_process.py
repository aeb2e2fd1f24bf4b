"""The tick process's entry points: a cold start, a spare's prepared loop, serving it.

The edge of the tick: signals (:class:`Signals`: in the spawned tick SIGTERM is an e-stop
and SIGINT the web process's to decide; in ``rig --drive``, which runs this loop in its own
process, both are an e-stop), real-time priority, the frozen collector, the devices
connected; the loop itself is :class:`~riderlive.realtime.tick.TickLoop`.
"""

from __future__ import annotations

import contextlib
import enum
import gc
import logging
import os
import signal
import threading
import time
from multiprocessing.connection import Connection
from typing import Any

from riderlive.devices.board import SafetyBoard
from riderlive.devices.guardians import stop_wait_s
from riderlive.devices.latch import StopLatch, StopSource
from riderlive.realtime import commands as cmd
from riderlive.realtime.last_words import last_words
from riderlive.realtime.output import TickDevices
from riderlive.realtime.setup import TickSetup
from riderlive.realtime.tick import TickLoop
from riderlive.sched import normal_priority_thread, try_realtime_priority


def tick_main(setup: TickSetup, commands: Connection, notify: Connection) -> None:
    """Entry point of the spawned tick process (a cold start: the first generation, or one
    with no warm spare ready; in the web process itself with ``tick.isolation = "thread"``)."""
    if threading.current_thread() is threading.main_thread():
        logging.basicConfig(level=logging.INFO, format="%(levelname)s tick: %(message)s")
    with last_words(f"tick generation {setup.generation}"):
        serve(prepare(setup, commands, notify.fileno()))


def prepare(setup: TickSetup, commands: Connection, notify_fd: int) -> TickLoop:
    """The loop, attached to the shared memory, without devices and not warmed yet."""
    os.set_blocking(notify_fd, False)
    latch = StopLatch(setup.latch_name) if setup.latch_name else StopLatch()
    board = SafetyBoard(setup.board_name) if setup.board_name else None
    return TickLoop(setup, commands, notify_fd, None, latch=latch, board=board)


def discard(loop: TickLoop) -> None:
    """Detach a loop that never ran (a spare's warm-up loop replaced at takeover)."""
    loop.close()
    loop.latch.close()
    if loop.board is not None:
        loop.board.close()


class Signals(enum.Enum):
    """What SIGINT and SIGTERM mean to a tick run in a process's main thread."""

    SERVICE = "service"
    """The spawned tick of ``serve``: SIGINT is the web process's to decide (ignored); SIGTERM
    of the driving process is an e-stop, then a stop."""
    OPERATOR = "operator"
    """A tick an operator runs (``rig --drive``): SIGINT (Ctrl-C) and SIGTERM are an e-stop
    (recorded in the latch, acted on at once: the loop wakes on the signal); whoever runs it
    stops the loop once the outputs are off."""


def serve(loop: TickLoop, warmed: bool = False, signals: Signals = Signals.SERVICE) -> None:
    """Connect the devices (disarmed; armed once with ``serve --arm`` in the first generation
    only), warm the kernels unless ``warmed``, and run until stopped; then detach. In the
    main thread it owns the process's edge for the run (``signals``, real-time priority, the
    frozen collector) and gives it back afterwards."""
    setup = loop.setup
    latch, board = loop.latch, loop.board
    in_process = threading.current_thread() is threading.main_thread()
    edge = _ProcessEdge(loop, signals) if in_process else contextlib.nullcontext()
    try:
        with edge:
            devices: TickDevices | None = None
            if setup.devices:
                arm = setup.arm_on_start if setup.generation == 1 else None
                devices = loop.devices = TickDevices(setup.devices, latch, board, setup.guardian, arm)
                for name, changes in setup.tunes.items():  # live parameters applied before this generation
                    reply = devices.request(cmd.Tune(name, changes, "restart"))
                    if not reply.ok:
                        message = f"{name}: the live parameters kept from before were refused: {reply.message}"
                        loop.events.append(message)
            # The parts and physics kernels compile (cold cache) or load here: before real-time priority
            # (a 10-20 s compile at FIFO would starve the web process), before the collector is
            # frozen (compiling makes cyclic garbage) and before the first deadline.
            if not warmed:
                loop.warm()
            if not (warmed and loop.realtime == "fifo"):  # a spare asked before it blocked
                loop.realtime = try_realtime_priority() if setup.realtime_priority else "off"
            if in_process:
                # The loop makes no reference cycles: refcounting frees everything, and a
                # collection of the whole heap would stall a tick for milliseconds.
                gc.collect()
                gc.freeze()
                gc.disable()
            if devices is not None:
                devices.open(stop_wait_s(setup.park_timeout))
            loop.run()
    finally:
        loop.close()
        latch.close()
        if board is not None:
            board.close()


class _ProcessEdge:
    """The main thread's edge for one run: signal handlers and the signal wake-up pipe (the
    loop sleeps on it), then, on the way out, the handlers, the wake-up fd, the collector and
    normal scheduling as they were (a tick in a process that goes on: ``rig --drive``'s tests)."""

    def __init__(self, loop: TickLoop, signals: Signals) -> None:
        self.loop = loop
        self.signals = signals
        self._handlers: dict[int, Any] = {}
        self._fds = (-1, -1)
        self._wakeup = -1

    def __enter__(self) -> None:
        loop, latch = self.loop, self.loop.latch
        logging.basicConfig(level=logging.INFO, format="%(levelname)s tick: %(message)s")
        self._fds = wake_read, wake_write = os.pipe()
        os.set_blocking(wake_read, False)
        os.set_blocking(wake_write, False)
        self._wakeup = signal.set_wakeup_fd(wake_write, warn_on_full_buffer=False)
        loop.wake_fds.append(wake_read)
        start = loop.setup.start

        def estop(signum: int, frame: object) -> None:  # recorded now; the loop wakes and acts on it
            latch.request(StopSource.SIGNAL)

        def estop_then_stop(signum: int, frame: object) -> None:  # SIGTERM of the driving process
            latch.request(StopSource.SIGNAL)
            loop._begin_stop(time.perf_counter() - start)

        if self.signals is Signals.SERVICE:
            handlers: dict[int, Any] = {signal.SIGINT: signal.SIG_IGN, signal.SIGTERM: estop_then_stop}
        else:
            handlers = {signal.SIGINT: estop, signal.SIGTERM: estop}
        self._handlers = {sig: signal.signal(sig, handler) for sig, handler in handlers.items()}

    def __exit__(self, *exc: object) -> None:
        for sig, handler in self._handlers.items():
            signal.signal(sig, handler)
        signal.set_wakeup_fd(self._wakeup)
        self.loop.wake_fds.remove(self._fds[0])
        for fd in self._fds:
            os.close(fd)
        gc.enable()
        gc.unfreeze()
        if self.loop.realtime == "fifo":
            normal_priority_thread()
