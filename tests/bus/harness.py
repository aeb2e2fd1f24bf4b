"""A real nats-server, real ``riderlive serve --nats`` rigs and a NATS client on its own loop."""

from __future__ import annotations

import asyncio
import contextlib
import threading
import time
from collections.abc import Callable, Coroutine
from concurrent.futures import Future
from pathlib import Path
from typing import Any, TypeVar

from riderlive.bus.nats import Credentials, NatsTransport, connect
from riderlive.bus.transport import Message
from tests.service.live_server import LiveServer
from tests.waiting import wait_until

T = TypeVar("T")
TOKEN = "stage-token-123"
TOKEN_CONFIG = f"""
[tick]
rate = 100.0
realtime_priority = false

[input]
producer_timeout = 0.3
max_message_bytes = 4096

[security]
token = "{TOKEN}"
require_token = true
"""
"""A rig's service config on a stage: the token always required, small message limit."""
AUTH = {"Authorization": f"Bearer {TOKEN}"}
RIG_TICK = """
[tick]
rate = 100.0
realtime_priority = false

[input]
producer_timeout = 0.3
"""


class NatsProbe:
    """A NATS connection on an event loop in a thread; ``call`` runs a coroutine there."""

    def __init__(self, url: str, credentials: Credentials | None = None) -> None:
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.transport: NatsTransport = self.call(connect(url, credentials or Credentials(), "test probe"))
        self.received: dict[str, list[tuple[float, Message]]] = {}
        self._tasks: list[asyncio.Task[Any]] = []

    def call(self, coro: Coroutine[Any, Any, T], timeout: float = 20.0) -> T:
        future: Future[T] = asyncio.run_coroutine_threadsafe(coro, self.loop)
        return future.result(timeout)

    def collect(self, subject: str) -> list[tuple[float, Message]]:
        """Keep every message on ``subject`` (with its perf_counter arrival time)."""
        box: list[tuple[float, Message]] = self.received.setdefault(subject, [])

        async def keep(msg: Message) -> None:
            box.append((time.perf_counter(), msg))

        async def sub() -> None:
            await self.transport.subscribe(subject, keep, 1 << 16)
            await self.transport.flush()

        self.call(sub())
        return box

    def publish(self, subject: str, data: bytes) -> None:
        async def pub() -> None:
            await self.transport.publish(subject, data)
            await self.transport.flush()

        self.call(pub())

    def request(self, subject: str, data: bytes, timeout: float = 5.0) -> bytes:
        return self.call(self.transport.request(subject, data, timeout), timeout + 5.0)

    def start(self, make: Callable[[], Coroutine[Any, Any, Any]]) -> asyncio.Task[Any]:
        async def spawn() -> asyncio.Task[Any]:
            return asyncio.get_running_loop().create_task(make())

        task = self.call(spawn())
        self._tasks.append(task)
        return task

    def close(self) -> None:
        for task in self._tasks:
            self.loop.call_soon_threadsafe(task.cancel)
        with contextlib.suppress(Exception):
            self.call(self.transport.close(), 5.0)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(5.0)


def nats_section(url: str, stage: str, rig: str, extra: str = "") -> str:
    return f'\n[nats]\nurl = "{url}"\nstage = "{stage}"\nrig = "{rig}"\n{extra}\n'


def start_rig(
    workdir: Path, url: str, stage: str, rig: str, config: str = RIG_TICK, extra: str = "", **kw: Any
) -> LiveServer:
    workdir.mkdir(parents=True, exist_ok=True)
    return LiveServer(config + nats_section(url, stage, rig, extra), workdir, **kw)


def wait_for(what: Callable[[], Any], timeout: float = 10.0, say: Callable[[], object] = lambda: None) -> Any:
    value = None

    def check() -> bool:
        nonlocal value
        value = what()
        return bool(value)

    wait_until(check, timeout, say, poll=0.02)
    return value
