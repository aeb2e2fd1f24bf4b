"""The web process's handle on the tick process: spawn, rings, commands, shutdown.

The shared memory (rings, counters, status, the e-stop latch and the safety board)
outlives any one tick process: after a crash or a hang the supervisor
(``riderlive.service.supervisor``) calls :meth:`TickLink.respawn`, which starts the
next *generation* on the same memory with fresh pipes. Requests that want an answer
(arm, disarm, reset, reload) travel on the duplex command pipe; the tick's replies
come back on it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import multiprocessing
import os
import signal
import threading
import time
from multiprocessing.connection import Connection
from typing import Any

import numpy as np
import orjson

from riderlive.devices.board import SafetyBoard
from riderlive.devices.latch import StopLatch
from riderlive.realtime import commands as cmd
from riderlive.realtime import latency
from riderlive.realtime import layout as L
from riderlive.realtime.setup import TickSetup
from riderlive.realtime.shm import SharedBlob, SharedCounters, SharedRing
from riderlive.realtime.tick import tick_main


class TickLink:
    """Owns the shared memory and the tick process; used from the web process only."""

    def __init__(self, setup: TickSetup) -> None:
        self.inputs = SharedRing(L.INPUT_CAPACITY, L.INPUT_WIDTH)
        self.outputs = SharedRing(L.OUTPUT_CAPACITY, L.OUTPUT_WIDTH + len(setup.extra_channels))
        self.counters = SharedCounters(L.COUNTERS)
        self.histogram_block = SharedCounters(latency.slot_names(latency.TICK_HISTOGRAMS))
        self.histograms = latency.views(self.histogram_block.values, latency.TICK_HISTOGRAMS)
        """Filled by the tick: ``tick_lateness``, ``ingest_to_wire``, ``ingest_to_tick`` (``realtime.latency``)."""
        self.status_blob = SharedBlob()
        self.latch = StopLatch()
        self.board = SafetyBoard()
        self.board["web_pid"] = float(os.getpid())
        names = {
            "input": self.inputs.name,
            "output": self.outputs.name,
            "counters": self.counters.name,
            "histograms": self.histogram_block.name,
            "status": self.status_blob.name,
        }
        self.base_setup = dataclasses.replace(
            setup, shm_names=names, latch_name=self.latch.name, board_name=self.board.name
        )
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
        self.respawn()

    def respawn(self) -> None:
        """Start the next generation of the tick (the first one from ``__init__``)."""
        if self.generation:
            self._commands.close()
            self._notify.close()
        self.generation += 1
        self.setup = dataclasses.replace(self.base_setup, generation=self.generation)
        self.board.forget_devices()
        self.board["tick_beat"] = 0.0
        context = multiprocessing.get_context("spawn")
        self._commands, child_commands = context.Pipe(duplex=True)
        notify_read, notify_write = context.Pipe(duplex=False)
        self._notify = notify_read
        self.notify_fd = notify_read.fileno()
        args = (self.setup, child_commands, notify_write)
        if self.setup.isolation == "thread":
            self.process = threading.Thread(target=tick_main, args=args, name="riderlive-tick", daemon=True)
            self.process.start()
            self.board["tick_pid"] = float(os.getpid())
        else:
            self.process = context.Process(target=tick_main, args=args, name="riderlive-tick", daemon=True)
            self.process.start()
            child_commands.close()
            notify_write.close()
            self.board["tick_pid"] = float(self.process.pid or 0)
        self.board["tick_generation"] = float(self.generation)
        os.set_blocking(self.notify_fd, False)

    @property
    def start(self) -> float:
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
    ) -> None:
        """Hand one validated horse frame, or saddle sample (six values), in service length units to the tick."""
        record = np.full(L.INPUT_WIDTH, np.nan)
        record[L.IN_PRODUCER] = producer
        record[L.IN_T] = t
        record[L.IN_RECEIVED] = received
        record[L.IN_KIND] = kind
        record[L.IN_VALUES : L.IN_VALUES + len(values)] = values
        self.inputs.write(record)

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
        """The tick's latest status (driver, mode, e-stop, devices...)."""
        version = self.status_blob.version
        if version != self._status_version:
            data = self.status_blob.read()
            if data is not None:
                self._status = orjson.loads(data)
                self._status_version = version
        return self._status

    def alive(self) -> bool:
        return self.process.is_alive()

    def beat_age(self) -> float | None:
        """Seconds since the tick's last heartbeat (None before its first)."""
        beat = self.board["tick_beat"]
        return None if not beat else time.perf_counter() - beat

    def exit_reason(self) -> str:
        """How the tick process ended: ``exit 1``, ``SIGKILL``..., or ``running``."""
        if isinstance(self.process, threading.Thread):
            return "running" if self.process.is_alive() else "thread ended"
        code = self.process.exitcode
        if code is None:
            return "running"
        if code < 0:
            with contextlib.suppress(ValueError):
                return signal.Signals(-code).name
            return f"signal {-code}"
        return f"exit {code}"

    def kill(self) -> None:
        """SIGKILL the tick process (a hung one) and reap it."""
        if isinstance(self.process, threading.Thread) or self.process.pid is None:
            return
        with contextlib.suppress(ProcessLookupError):
            os.kill(self.process.pid, signal.SIGKILL)
        self.process.join(2.0)

    def stop(self, timeout: float) -> None:
        """Ask the tick to park and stop; wait up to ``timeout`` seconds, then kill it."""
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
        self.histograms.clear()
        for shared in (self.inputs, self.outputs, self.counters, self.histogram_block, self.status_blob):
            shared.close()
        self.latch.close()
        self.board.close()
