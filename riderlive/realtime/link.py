"""The web process's handle on the tick process: spawn, rings, commands, shutdown."""

from __future__ import annotations

import contextlib
import dataclasses
import multiprocessing
import os
import threading
import time
from typing import Any

import numpy as np
import orjson

from riderlive.realtime import commands as cmd
from riderlive.realtime import layout as L
from riderlive.realtime.shm import SharedBlob, SharedCounters, SharedRing
from riderlive.realtime.tick import TickSetup, tick_main


class TickLink:
    """Owns the shared memory and the tick process; used from the web process only."""

    def __init__(self, setup: TickSetup) -> None:
        self.inputs = SharedRing(L.INPUT_CAPACITY, L.INPUT_WIDTH)
        self.outputs = SharedRing(L.OUTPUT_CAPACITY, L.OUTPUT_WIDTH + len(setup.extra_channels))
        self.counters = SharedCounters(L.COUNTERS)
        self.status_blob = SharedBlob()
        names = {
            "input": self.inputs.name,
            "output": self.outputs.name,
            "counters": self.counters.name,
            "status": self.status_blob.name,
        }
        self.setup = dataclasses.replace(setup, shm_names=names)
        context = multiprocessing.get_context("spawn")
        self._commands, child_commands = context.Pipe(duplex=True)
        notify_read, notify_write = context.Pipe(duplex=False)
        self._notify = notify_read
        self.notify_fd = notify_read.fileno()
        args = (self.setup, child_commands, notify_write)
        self.process: multiprocessing.process.BaseProcess | threading.Thread
        if setup.isolation == "thread":
            self.process = threading.Thread(target=tick_main, args=args, name="riderlive-tick", daemon=True)
            self.process.start()
        else:
            self.process = context.Process(target=tick_main, args=args, name="riderlive-tick", daemon=True)
            self.process.start()
            child_commands.close()
            notify_write.close()
        os.set_blocking(self.notify_fd, False)
        self.outputs.read_next = 0
        self._status_version = -1
        self._status: dict[str, Any] = {}

    @property
    def start(self) -> float:
        return self.setup.start

    def engine_time(self) -> float:
        return time.perf_counter() - self.setup.start

    def send(self, command: cmd.Command) -> None:
        self._commands.send(command)

    def push_input(self, producer: int, t: float, received: float, values: list[float] | np.ndarray) -> None:
        """Hand one validated horse frame (service length units) to the tick."""
        record = np.empty(L.INPUT_WIDTH)
        record[L.IN_PRODUCER] = producer
        record[L.IN_T] = t
        record[L.IN_RECEIVED] = received
        record[L.IN_VALUES :] = values
        self.inputs.write(record)

    def drain_notify(self) -> None:
        try:
            while os.read(self.notify_fd, 65536):
                pass
        except BlockingIOError:
            pass

    def read_outputs(self, limit: int | None = None) -> list[np.ndarray]:
        """Output records written since the last call."""
        return self.outputs.read_new(limit)

    def status(self) -> dict[str, Any]:
        """The tick's latest status (driver, mode, e-stop, rig...)."""
        version = self.status_blob.version
        if version != self._status_version:
            data = self.status_blob.read()
            if data is not None:
                self._status = orjson.loads(data)
                self._status_version = version
        return self._status

    def alive(self) -> bool:
        return self.process.is_alive()

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
        for shared in (self.inputs, self.outputs, self.counters, self.status_blob):
            shared.close()
