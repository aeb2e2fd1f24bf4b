"""The tick process's entry points: a cold start, a spare's prepared loop, serving it.

The edge of the tick: signals (SIGTERM is an e-stop, SIGINT is the web process's to
decide), real-time priority, the frozen collector, the devices connected; the loop itself
is :class:`~riderlive.realtime.tick.TickLoop`.
"""

from __future__ import annotations

import gc
import logging
import os
import signal
import threading
import time
from multiprocessing.connection import Connection

from riderlive.devices.board import SafetyBoard
from riderlive.devices.latch import StopLatch, StopSource
from riderlive.realtime import commands as cmd
from riderlive.realtime.output import TickDevices
from riderlive.realtime.pacing import try_realtime_priority
from riderlive.realtime.setup import TickSetup
from riderlive.realtime.spare import last_words
from riderlive.realtime.tick import TickLoop


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


def serve(loop: TickLoop, warmed: bool = False) -> None:
    """Connect the devices (disarmed; armed once with ``serve --arm`` in the first generation
    only), warm the kernels unless ``warmed``, and run until stopped; then detach."""
    setup = loop.setup
    in_process = threading.current_thread() is threading.main_thread()
    if in_process:
        logging.basicConfig(level=logging.INFO, format="%(levelname)s tick: %(message)s")
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # the web process decides when to stop
    latch, board = loop.latch, loop.board
    devices: TickDevices | None = None
    if setup.devices:
        arm = setup.arm_on_start if setup.generation == 1 else None
        devices = loop.devices = TickDevices(setup.devices, latch, board, setup.guardian, arm)
        for name, changes in setup.tunes.items():  # live parameters applied before this generation
            reply = devices.request(cmd.Tune(name, changes, "restart"))
            if not reply.ok:
                loop.events.append(f"{name}: the live parameters kept from before were refused: {reply.message}")
    if in_process:
        wake_read, wake_write = os.pipe()
        os.set_blocking(wake_read, False)
        os.set_blocking(wake_write, False)
        signal.set_wakeup_fd(wake_write, warn_on_full_buffer=False)
        loop.wake_fds.append(wake_read)

        def on_term(signum: int, frame: object) -> None:  # SIGTERM of the driving process: e-stop
            latch.request(StopSource.SIGNAL)
            loop._begin_stop(time.perf_counter() - setup.start)

        signal.signal(signal.SIGTERM, on_term)
    try:
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
            devices.open()
        loop.run()
    finally:
        loop.close()
        latch.close()
        if board is not None:
            board.close()
