"""The warm spare: a tick process imported, attached and with its kernels loaded, waiting to take over.

A cold tick spends ~1.6 s of CPU before its first frame (imports ~0.8 s, loading the
compiled rider parts and physics kernels ~0.8 s; docs/performance.md), several seconds
on a loaded host. The web process (``realtime/link.py``) therefore keeps one spare beside
the running tick:

1. **warm-up**, in a thread at ``nice`` (a per-thread nice value on Linux: the warm-up
   does not take the running tick's CPU on a busy host, and the process's main thread
   keeps its normal priority for later, without privileges): the imports, a
   :class:`~riderlive.realtime.tick.TickLoop` built from the setup the spare was started
   with, attached to the shared memory, its kernels warmed. Then :class:`Warm` on the
   command pipe;
2. **waiting**, blocked in ``recv`` on its command pipe: no CPU at all;
3. **takeover** on :class:`TakeOver` (the setup as the service reports it now, pickled,
   and the new generation): a loop rebuilt if the settings changed since the warm-up
   (cheap: the kernels are loaded), the newest snapshot of the dead generation restored
   (``realtime/handover.py``), then the devices connected disarmed, real-time priority
   and the loop, exactly as a cold tick (``tick_process.serve``).

The pipe closing (the web process gone or the spare not wanted) ends it at any stage.
This module imports only the standard library: the spawned process's main thread
unpickles its arguments before anything else, at normal priority.
"""

from __future__ import annotations

import contextlib
import dataclasses
import gc
import logging
import multiprocessing.process
import os
import pickle
import signal
import threading
import time
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any

from riderlive.realtime.last_words import last_words

log = logging.getLogger("riderlive.realtime.tick")
WARM_NICE = 10
"""Nice value of the warm-up thread (``serve`` on a busy host: ~10 % of a core's share)."""


@dataclass(frozen=True)
class Warm:
    """Spare -> web: imported and warmed; ``cpu_s``/``wall_s`` the warm-up's cost."""

    pid: int
    cpu_s: float
    wall_s: float


@dataclass(frozen=True)
class TakeOver:
    """Web -> spare: become the running tick with this setup (a pickled ``TickSetup``)."""

    setup: bytes


@dataclass(frozen=True)
class Failed:
    """Spare -> web: the warm-up failed (the message says why); the spare exits."""

    message: str


@dataclasses.dataclass
class Spare:
    """The web side of a spare tick process (``realtime/spare.py``)."""

    process: multiprocessing.process.BaseProcess
    commands: Connection
    notify: Connection
    started_at: float
    """perf_counter s."""
    urgent: bool
    warm: Warm | None = None
    failed: str | None = None

    def poll(self) -> None:
        """Take the spare's messages (``Warm``, ``Failed``) without waiting."""
        with contextlib.suppress(EOFError, OSError):
            while self.warm is None and self.failed is None and self.commands.poll():
                message = self.commands.recv()
                if isinstance(message, Warm):
                    self.warm = message
                elif isinstance(message, Failed):
                    self.failed = message.message

    @property
    def ready(self) -> bool:
        self.poll()
        return self.warm is not None and self.process.is_alive()

    def discard(self) -> None:
        """Close its pipes (it exits when it sees them close) and make sure it is gone."""
        self.commands.close()
        self.notify.close()
        if self.process.is_alive():
            self.process.kill()
        self.process.join(1.0)


def spare_main(setups: tuple[bytes, ...], commands: Connection, notify: Connection, nice: int = WARM_NICE) -> None:
    """Entry point of a spare process. ``setups``: pickled ``TickSetup`` objects to warm up with,
    the first that works (the settings as applied, then as configured: a setting that fails
    here fails at the takeover too, where the supervisor deals with it)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the web process decides when to stop
    logging.basicConfig(level=logging.INFO, format="%(levelname)s tick: %(message)s")
    with last_words("the spare tick"):
        _spare(setups, commands, notify, nice)


def _spare(setups: tuple[bytes, ...], commands: Connection, notify: Connection, nice: int) -> None:
    box: dict[str, Any] = {}
    started, cpu0 = time.perf_counter(), time.process_time()

    def warm_up() -> None:
        if nice:
            with contextlib.suppress(OSError):  # this thread only (Linux): the main thread keeps its priority
                os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), nice)
        from riderlive.realtime import tick_process as tick

        for setup in setups:
            try:
                loop = tick.prepare(pickle.loads(setup), commands, notify.fileno())
                loop.warm()
            except Exception as exc:
                box["error"] = f"{type(exc).__name__}: {exc}"
                continue
            box["loop"] = loop
            # A collection of the whole heap costs ~0.3-1 s (numba's objects): done here, and
            # what survives frozen, so the takeover's own collection sees only its new objects.
            gc.collect()
            gc.freeze()
            return

    thread = threading.Thread(target=warm_up, name="riderlive-spare-warm-up")
    thread.start()
    thread.join()
    try:
        if "loop" not in box:
            commands.send(Failed(box["error"]))
            raise SystemExit(1)
        if box["loop"].setup.realtime_priority:
            # Blocked, a real-time thread costs nothing; woken, it runs at once (a busy host would
            # make a normal one wait for its turn before the takeover has even begun).
            from riderlive.sched import try_realtime_priority

            box["loop"].realtime = try_realtime_priority(who="the spare tick")
        commands.send(Warm(os.getpid(), time.process_time() - cpu0, time.perf_counter() - started))
        message = commands.recv()  # blocked here until needed: no CPU
    except (EOFError, OSError):  # the web process is gone, or does not want this spare
        return
    if isinstance(message, TakeOver):
        take_over(box["loop"], pickle.loads(message.setup))


def take_over(loop: Any, setup: Any) -> None:
    """Become generation ``setup.generation``: rebuild the loop if the settings changed, restore
    the dead generation's snapshot, serve."""
    from riderlive.realtime import handover
    from riderlive.realtime import tick_process as tick

    began = time.perf_counter()
    rebuilt = dataclasses.replace(loop.setup, generation=setup.generation) != setup
    if rebuilt:
        fresh = tick.prepare(setup, loop.commands, loop.notify_fd)
        fresh.realtime = loop.realtime
        tick.discard(loop)
        loop = fresh
        loop.warm()  # the kernels are loaded in this process: fast
    else:
        loop.setup = setup
    snapshot = None if loop.handover_blob is None else handover.decode(loop.handover_blob.read())
    replayed = loop.take_over(snapshot)
    tail = snapshot is not None and handover.restore_tail(loop.physics, snapshot)
    log.info(
        "generation %d took over in %.1f ms (%s, %s, %d input records replayed, tail %s)",
        setup.generation,
        (time.perf_counter() - began) * 1000,
        "settings changed: loop rebuilt" if rebuilt else "same settings",
        "no snapshot" if snapshot is None else f"state of generation {snapshot.generation}",
        replayed,
        "handed over" if tail else "from rest",
    )
    tick.serve(loop, warmed=True)
