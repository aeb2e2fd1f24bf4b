"""The web process's handle on the tick process: spawn, rings, commands, shutdown.

The shared memory (rings, counters, status, the handover snapshot, the e-stop latch and
the safety board) outlives any one tick process. Beside the running tick waits a warm
spare (``realtime/spare.py``: imported, kernels loaded, blocked on its pipe); after a
crash or a hang the supervisor (``riderlive.service.supervisor``) calls
:meth:`TickLink.promote`, which makes the spare the next *generation*: it gets the
settings as the service reports them (:meth:`apply`) and the dead generation's state
(``realtime/handover.py``), then :meth:`start_spare` warms the next spare in the
background. Without a spare ready, a spare is started at normal priority and promoted at
once (a cold start). Requests that want an answer (arm, disarm, reset, reload) travel on
the duplex command pipe; the tick's replies come back on it.

From a failure until the next generation's first heartbeat (:meth:`mark_down`,
:meth:`mark_up`), :meth:`status` reports the tick down and each device as the guardian
reports it (``realtime/down.py``), never the dead generation's status.
"""

from __future__ import annotations

import contextlib
import dataclasses
import multiprocessing
import os
import pickle
import signal
import threading
import time
from multiprocessing.connection import Connection
from typing import Any

import numpy as np
import orjson

from riderlive.realtime import commands as cmd
from riderlive.realtime import layout as L
from riderlive.realtime.down import down_status
from riderlive.realtime.memory import TickMemory
from riderlive.realtime.setup import TickSetup
from riderlive.realtime.spare import Spare, TakeOver, spare_main
from riderlive.realtime.tick_process import tick_main

EXIT_255 = (
    "exit 255: exit(-1) (SystemExit(-1), or a C library's exit(-1)) or its exec failed before Python ran"
    " (multiprocessing's spawn says nothing then); the log above says which: a 'last words' line"
    " with a traceback, a faulthandler dump, or no 'started' line for that pid"
)
"""What ``exit 255`` can mean (the soak saw one once, its log not kept: ``realtime/last_words.py``)."""


def exit_reason(code: int | None) -> str:
    """A process's ``exitcode`` said: ``exit 1``, ``SIGKILL``..., ``exit 255`` with what it can
    mean (:data:`EXIT_255`), or ``running`` (None)."""
    if code is None:
        return "running"
    if code < 0:
        with contextlib.suppress(ValueError):
            return signal.Signals(-code).name
        return f"signal {-code}"
    return EXIT_255 if code == 255 else f"exit {code}"


class TickLink(TickMemory):
    """Owns the shared memory (:class:`~riderlive.realtime.memory.TickMemory`) and the tick
    process; used from the web process only."""

    def __init__(self, setup: TickSetup) -> None:
        super().__init__(setup.layout.width)
        self.board.web_pid = os.getpid()
        self.base_setup = self.attach(setup)
        self.start_setup = self.setup = self.base_setup
        """``start_setup``: as configured; ``base_setup``: with what :meth:`apply` kept since."""
        self.generation = 0
        self.process: multiprocessing.process.BaseProcess | threading.Thread
        self._commands: Connection
        self._notify: Connection
        self.notify_fd = -1
        self.outputs.read_next = 0
        self._status_version = -1
        self._status: dict[str, Any] = {}
        self.spare: Spare | None = None
        self.spares_started = 0
        self.spares_failed = 0
        """Spares that died or failed their warm-up (each is replaced)."""
        self.takeovers = 0
        """Generations started from a spare that was warm when promoted."""
        self.down_reason: str | None = None
        """Why no generation is serving now (None: one is)."""
        self.respawn()

    @property
    def spares_wanted(self) -> bool:
        """A warm spare is kept: a tick process with ``tick.spare`` on."""
        return self.setup.isolation == "process" and self.setup.spare

    @property
    def cold_failover(self) -> bool:
        """A tick process without a spare (``tick.spare`` off): every failover is a cold start."""
        return self.setup.isolation == "process" and not self.setup.spare

    def start_spare(self, urgent: bool = False) -> Spare:
        """Start a spare with the settings as they are now (``urgent``: at normal priority, to
        be promoted at once), replacing one that is there."""
        if self.spare is not None:
            self.spare.discard()
        context = multiprocessing.get_context("spawn")
        commands, child_commands = context.Pipe(duplex=True)
        notify_read, notify_write = context.Pipe(duplex=False)
        setups = tuple(pickle.dumps(s, protocol=pickle.HIGHEST_PROTOCOL) for s in (self.base_setup, self.start_setup))
        args = (setups, child_commands, notify_write, 0 if urgent else self.base_setup.spare_nice)
        process = context.Process(target=spare_main, args=args, name="riderlive-tick-spare", daemon=True)
        process.start()
        child_commands.close()
        notify_write.close()
        self.spares_started += 1
        self.spare = Spare(process, commands, notify_read, time.perf_counter(), urgent)
        return self.spare

    def promote(self) -> bool:
        """Make the spare the next generation (after the running one is dead and its devices
        stopped); a spare started now at normal priority if none is there. True if the spare
        was warm (its first heartbeat is a tick away)."""
        if not self.spares_wanted:
            self.respawn()
            return False
        spare = self.spare
        if spare is not None:
            spare.poll()
            if spare.failed is not None or not spare.process.is_alive():
                self.spares_failed += 1
                spare.discard()
                spare = self.spare = None
        warm = spare is not None and spare.ready
        if spare is not None and not warm:  # still warming at its low priority: a cold start is sooner
            spare.discard()
            spare = self.spare = None
        if spare is None:
            spare = self.start_spare(urgent=True)
        self.spare = None
        self._commands.close()
        self._notify.close()
        self._next_generation()
        self._commands, self._notify, self.process = spare.commands, spare.notify, spare.process
        self.notify_fd = self._notify.fileno()
        os.set_blocking(self.notify_fd, False)
        with contextlib.suppress(OSError, ValueError):  # it died just now: the supervisor sees its sentinel
            spare.commands.send(TakeOver(pickle.dumps(self.setup, protocol=pickle.HIGHEST_PROTOCOL)))
        self.board.tick_pid = spare.process.pid or 0
        self.board.tick_generation = self.generation
        self.takeovers += warm
        return warm

    def _next_generation(self) -> None:
        self.generation += 1
        self.setup = dataclasses.replace(self.base_setup, generation=self.generation)
        if not self.board.guardian_busy:  # else the guardian's park progress (a successor of it goes on from there)
            self.board.forget_devices()
        self.board.tick_beat = 0.0
        self.board.tick_io_until = 0.0  # the dead generation may have died inside a wait
        self.board.tick_io_waited = 0.0

    def mark_down(self, reason: str) -> None:
        """No generation serves from now (a death, a hang): :meth:`status` says so."""
        self.down_reason = reason
        board = self.board
        if max(board.guardian_taking, board.guardian_done) < self.generation:  # not yet this failure's reports
            board.clear_reports()

    def mark_up(self) -> None:
        """The serving generation has beaten."""
        self.down_reason = None

    def respawn(self) -> None:
        """Start the next generation of the tick cold (the first one from ``__init__``, and
        every one of a tick thread)."""
        if self.generation:
            self._commands.close()
            self._notify.close()
        self._next_generation()
        context = multiprocessing.get_context("spawn")
        self._commands, child_commands = context.Pipe(duplex=True)
        notify_read, notify_write = context.Pipe(duplex=False)
        self._notify = notify_read
        self.notify_fd = notify_read.fileno()
        args = (self.setup, child_commands, notify_write)
        if self.setup.isolation == "thread":
            self.process = threading.Thread(target=tick_main, args=args, name="riderlive-tick", daemon=True)
            self.process.start()
            self.board.tick_pid = os.getpid()
        else:
            self.process = context.Process(target=tick_main, args=args, name="riderlive-tick", daemon=True)
            self.process.start()
            child_commands.close()
            notify_write.close()
            self.board.tick_pid = self.process.pid or 0
        self.board.tick_generation = self.generation
        os.set_blocking(self.notify_fd, False)

    @property
    def start(self) -> float:
        """The host's ``CLOCK_MONOTONIC`` (s; ``time.perf_counter`` on Linux) at engine time 0."""
        return self.setup.start

    @property
    def commands_fd(self) -> int:
        """Readable when the tick has replied to a request."""
        return self._commands.fileno()

    @property
    def sentinel(self) -> int | None:
        """Readable once the tick process has exited (None for a tick thread)."""
        if isinstance(self.process, threading.Thread):
            return None
        return int(self.process.sentinel)

    def engine_time(self) -> float:
        """Seconds since the service started (every generation's tick keeps it)."""
        return time.perf_counter() - self.setup.start

    def send(self, command: cmd.Command) -> None:
        self._commands.send(command)

    def tell(self, command: cmd.Command) -> bool:
        """Send a command a restarted tick does not need (a producer gone, a one-off move);
        False, and nothing sent, when the tick is down."""
        try:
            self.send(command)
        except (OSError, ValueError):  # a broken or closed pipe: the tick is down
            return False
        return True

    def apply(self, command: cmd.Command, **setup: Any) -> None:
        """Send a command that changes what the tick runs (rule parameters, animator layer,
        mode, gait) and keep its effect, the ``setup`` fields of :class:`TickSetup`, for the
        next generation: a restarted tick starts as the service reports it, not as it was
        at start. A tick that is down (restarting) gets it at its respawn."""
        self.base_setup = dataclasses.replace(self.base_setup, **setup)
        with contextlib.suppress(OSError, ValueError):  # a broken or closed pipe: the tick is down
            self.send(command)

    def keep_tune(self, device: str, changes: dict[str, Any]) -> None:
        """A device's live parameters were changed (a ``Tune`` the tick accepted): the next
        generation applies them too."""
        tunes = dict(self.base_setup.tunes)
        tunes[device] = {**tunes.get(device, {}), **changes}
        self.base_setup = dataclasses.replace(self.base_setup, tunes=tunes)

    def forget_applied(self) -> bool:
        """The next generation starts as configured (what :meth:`apply` kept made a tick
        fail to start); False if there was nothing to forget."""
        if self.base_setup == self.start_setup:
            return False
        self.base_setup = self.start_setup
        return True

    def replies(self) -> list[cmd.Reply]:
        """The tick's replies that have arrived (call when ``commands_fd`` is readable)."""
        out = []
        with contextlib.suppress(EOFError, OSError):
            while self._commands.poll():
                message = self._commands.recv()
                if isinstance(message, cmd.Reply):
                    out.append(message)
        return out

    def push_input(
        self,
        producer: int,
        t: float,
        received: float,
        values: list[float] | np.ndarray,
        kind: L.InputKind = L.InputKind.HORSE,
        *,
        rebased: bool = False,
    ) -> None:
        """Hand one validated horse frame, or saddle sample (six values), in service length units to
        the tick (``rebased``: the producer's clock was re-anchored at it, ``service/clocks.py``)."""
        self.inputs.write(L.InputRecord(producer, t, received, list(values), kind, rebased).row())

    def input_pending(self, received: float | None) -> None:
        """An input received at ``received`` (``perf_counter`` seconds) is being turned into a
        record for the tick (None: done): the tick waits for it briefly (``pacing.pickup_until``)."""
        self.inputs.mark_pending(received)

    def drain_notify(self) -> None:
        try:
            while os.read(self.notify_fd, 65536):
                pass
        except (BlockingIOError, OSError):
            pass

    def read_outputs(self, limit: int | None = None) -> list[np.ndarray]:
        """Output records written since the last call."""
        return self.outputs.read_new(limit)

    def status(self) -> dict[str, Any]:
        """The serving tick's latest status (driver, mode, e-stop, devices...); while none
        serves, or before the new generation wrote one, the down status (``realtime/down.py``)."""
        version = self.status_blob.version
        if version != self._status_version:
            data = self.status_blob.read()
            if data is not None:
                self._status = orjson.loads(data)
                self._status_version = version
        if self.down_reason is None and self._status.get("generation", self.generation) == self.generation:
            return self._status
        devices = self.setup.devices
        reports = [self.board.reported(i) for i in range(len(devices))]
        return down_status(
            self._status,
            devices,
            reports,
            estop=self.latch.latched,
            reason=self.down_reason or "starting",
            generation=self.generation,
        )

    def alive(self) -> bool:
        return self.process.is_alive()

    def beat_age(self) -> float | None:
        """Seconds since the tick's last heartbeat (None before its first)."""
        beat = self.board.tick_beat
        return None if not beat else time.perf_counter() - beat

    def exit_reason(self) -> str:
        """How the tick process ended: ``exit 1``, ``SIGKILL``..., or ``running``."""
        if isinstance(self.process, threading.Thread):
            return "running" if self.process.is_alive() else "thread ended"
        return exit_reason(self.process.exitcode)

    def kill(self) -> None:
        """SIGKILL the tick process (a hung one). Not waited for: a killed process runs none of
        its code once the signal is sent (the kernel kicks it into its exit at once, stopped
        or not), and tearing a large one down takes tens of milliseconds that the next
        generation need not wait; it is reaped later (``multiprocessing`` reaps finished
        children at the next start, and :meth:`stop` joins)."""
        if isinstance(self.process, threading.Thread) or self.process.pid is None:
            return
        with contextlib.suppress(ProcessLookupError):
            os.kill(self.process.pid, signal.SIGKILL)

    def stop(self, timeout: float) -> None:
        """Ask the tick to park and stop; wait up to ``timeout`` seconds, then kill it (and the spare)."""
        if self.spare is not None:
            self.spare.discard()
            self.spare = None
        if self.process.is_alive():
            with contextlib.suppress(BrokenPipeError, OSError):
                self.send(cmd.Stop())
            self.process.join(timeout)
        if isinstance(self.process, threading.Thread):
            return
        if self.process.is_alive():
            self.process.terminate()
            self.process.join(1.0)
        if self.process.is_alive():
            self.process.kill()
            self.process.join(1.0)

    def close(self) -> None:
        self._commands.close()
        self._notify.close()
        if self.spare is not None:
            self.spare.discard()
            self.spare = None
        super().close()
