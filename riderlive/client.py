"""A small Python client for ``riderlive serve``, reconnecting by itself.

Subscribe to rider frames::

    async for frame in RiderSubscriber("ws://127.0.0.1:8000", channels=["head.rz"]).frames():
        print(frame.seq, frame.values["head.rz"])

Stream horse frames in::

    async with HorseProducer("ws://127.0.0.1:8000", name="mocap") as horse:
        await horse.send(t, {"rearPivot.rz": 2.0})

Or follow a rig on a stage over NATS: :class:`riderlive.bus.subscriber.NatsRiderSubscriber`.

Both reconnect with a capped exponential backoff when the service goes away;
``RiderSubscriber.restarted`` tells a reconnect to the same server (same session)
from a restarted one. The wire protocol is in docs/protocol.md.
"""

from __future__ import annotations

import asyncio
import json
import logging
from collections.abc import AsyncIterator, Callable, Sequence
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any

import msgpack
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidURI

_DECODE: list[Callable[[bytes], dict[str, Any]]] = []


def load_codecs() -> Callable[[bytes], dict[str, Any]]:
    """:func:`riderlive.service.rider_frames.decode_binary_frame`, imported when a subscriber is made, not
    with this module (the codecs pull in NumPy, pydantic and the horse model: seconds on a busy host):
    a tool that only probes or sends says a service is unreachable without waiting for them, and a
    subscriber never pauses on its first frame."""
    if not _DECODE:
        from riderlive.service.rider_frames import decode_binary_frame as decode

        _DECODE.append(decode)
    return _DECODE[0]


def time_left(timeout: float, least: float = 0.5) -> float:
    """What is left of ``timeout`` seconds counted from this process's start (Linux: its start time in
    ``/proc/self/stat``, so the interpreter's start and the imports count), at least ``least`` s."""
    import os
    import time

    try:
        with open("/proc/self/stat", "rb") as fh:
            start = int(fh.read().rsplit(b")", 1)[1].split()[19]) / os.sysconf("SC_CLK_TCK")
        ran = time.clock_gettime(time.CLOCK_BOOTTIME) - start
    except (OSError, ValueError, IndexError, AttributeError):
        ran = 0.0  # elsewhere: the whole timeout from now
    return max(least, timeout - ran)


def decode_binary_frame(message: bytes) -> dict[str, Any]:
    """One binary ``/ws/rider`` frame (:func:`riderlive.service.rider_frames.decode_binary_frame`)."""
    return load_codecs()(message)


log = logging.getLogger(__name__)
_RETRYABLE = (OSError, ConnectionClosed, InvalidHandshake, TimeoutError)
OPEN_TIMEOUT = 5.0
"""Seconds for a first connection (TCP, websocket handshake and the service's first message)."""


class ServiceUnreachable(ConnectionError):
    """The first connection to a service failed; ``str()`` says why in one line."""


def _unreachable(url: str, exc: BaseException, timeout: float) -> ServiceUnreachable:
    if isinstance(exc, InvalidURI):
        why = "not a websocket URL (use ws://HOST:PORT)"
    elif isinstance(exc, TimeoutError):
        why = f"no answer within {timeout:g} s"
    elif isinstance(exc, InvalidHandshake):
        why = f"not a riderlive service ({exc})"
    elif isinstance(exc, ValueError | KeyError):
        why = "not a riderlive service (unexpected first message)"
    else:
        why = str(exc) or type(exc).__name__
    return ServiceUnreachable(f"cannot reach riderlive at {url}: {why}")


async def probe(
    url: str = "ws://127.0.0.1:8000", path: str = "/ws/rider", token: str | None = None, timeout: float = OPEN_TIMEOUT
) -> dict[str, Any]:
    """Connect once and return the service's first message (hello or welcome).

    Raises :class:`ServiceUnreachable` with a one-line reason instead of retrying:
    for tools that should fail fast on a wrong ``--url``.
    """
    full = url.rstrip("/") + path
    try:
        async with asyncio.timeout(timeout):
            async with connect(full, subprotocols=_subprotocols(token), open_timeout=timeout) as ws:
                first = json.loads(await ws.recv())
                if not isinstance(first, dict) or first.get("type") not in ("hello", "welcome"):
                    raise ValueError("unexpected first message")
                return first
    except (InvalidURI, ValueError, KeyError, *_RETRYABLE) as exc:
        raise _unreachable(url, exc, timeout) from None


def _subprotocols(token: str | None) -> list[Any]:
    return ["riderlive.v1", f"riderlive.token.{token}"] if token else ["riderlive.v1"]


@dataclass
class Backoff:
    """Seconds to wait before reconnecting: doubles from ``first`` up to ``cap``."""

    first: float = 0.1
    cap: float = 5.0
    current: float = field(default=0.0, init=False)

    def next(self) -> float:
        self.current = self.first if self.current == 0.0 else min(self.cap, self.current * 2)
        return self.current

    def reset(self) -> None:
        self.current = 0.0


@dataclass(frozen=True)
class RiderFrame:
    """One rider frame: tick number, engine and source time (s), who drove, values by name."""

    seq: int
    t: float
    source_t: float
    driver: str
    values: dict[str, float]
    horse: dict[str, float]


class RiderSubscriber:
    """Follows ``/ws/rider``; see the module docstring."""

    def __init__(
        self,
        url: str = "ws://127.0.0.1:8000",
        *,
        channels: Sequence[str] | None = None,
        horse_channels: Sequence[str] = (),
        rate: float | None = None,
        encoding: str = "binary",
        token: str | None = None,
    ) -> None:
        self.url = url.rstrip("/") + "/ws/rider"
        self.subscribe: dict[str, Any] = {"type": "subscribe", "encoding": encoding}
        if channels is not None:
            self.subscribe["channels"] = list(channels)
        if horse_channels:
            self.subscribe["horse_channels"] = list(horse_channels)
        if rate is not None:
            self.subscribe["rate"] = rate
        self.token = token
        self.hello: dict[str, Any] = {}
        self.status: dict[str, Any] = {}
        self.restarted = False
        self.reconnects = 0
        self._names: list[str] = []
        self._horse_names: list[str] = []
        self._subscribed = False
        self._closed = False
        load_codecs()

    def close(self) -> None:
        self._closed = True

    async def frames(self) -> AsyncIterator[RiderFrame]:
        """Rider frames until :meth:`close`; reconnects across restarts of the service."""
        backoff = Backoff()
        connected_before = False
        while not self._closed:
            try:
                async with connect(self.url, subprotocols=_subprotocols(self.token), max_size=2**22) as ws:
                    await self._start(ws)
                    self.reconnects += connected_before
                    connected_before = True
                    backoff.reset()
                    async for message in ws:
                        frame = self._frame(message)
                        if frame is not None:
                            yield frame
                        if self._closed:
                            return
                reason = "closed by the server"
            except InvalidURI:
                raise
            except _RETRYABLE as exc:
                reason = str(exc)
            if not self._closed:
                delay = backoff.next()
                log.info("rider stream lost (%s); reconnecting in %.1f s", reason, delay)
                await asyncio.sleep(delay)

    async def _start(self, ws: ClientConnection) -> None:
        hello = json.loads(await ws.recv())
        self.restarted = bool(self.hello) and hello.get("session") != self.hello.get("session")
        self.hello = hello
        self._names = [c["name"] for c in hello["channels"]]
        self._horse_names = []
        self._subscribed = False
        await ws.send(json.dumps(self.subscribe))

    def _frame(self, message: str | bytes) -> RiderFrame | None:
        obj = decode_binary_frame(message) if isinstance(message, bytes) else json.loads(message)
        kind = obj.get("type")
        if kind == "subscribed":
            self._names = obj["channels"]
            self._horse_names = obj["horse_channels"]
            self._subscribed = True
        elif kind == "status":
            self.status = obj
        elif kind == "frame" and self._subscribed:  # frames before the ack use the defaults
            return RiderFrame(
                seq=obj["seq"],
                t=obj["t"],
                source_t=obj["source_t"],
                driver=obj["driver"],
                values=dict(zip(self._names, obj["values"], strict=False)),
                horse=dict(zip(self._horse_names, obj.get("horse", []), strict=False)),
            )
        return None


class HorseProducer:
    """Sends horse frames to ``/ws/horse`` (msgpack by default), reconnecting on failure.

    A frame sent while disconnected is dropped (live data is not queued); ``send``
    returns whether it went out. ``driving`` follows the server's control messages.
    """

    def __init__(
        self,
        url: str = "ws://127.0.0.1:8000",
        *,
        name: str = "python",
        priority: int = 0,
        length_scale: float | None = None,
        token: str | None = None,
        binary: bool = True,
        open_timeout: float = OPEN_TIMEOUT,
    ) -> None:
        self.url = url.rstrip("/") + "/ws/horse"
        self.hello: dict[str, Any] = {"type": "hello", "name": name, "priority": priority}
        if length_scale is not None:
            self.hello["length_scale"] = length_scale
        self.token = token
        self.binary = binary
        self.open_timeout = open_timeout
        self.driving: bool | None = None
        self.errors: list[dict[str, Any]] = []
        self._ws: ClientConnection | None = None
        self._reader: asyncio.Task[None] | None = None
        self._backoff = Backoff()
        self._retry_at = 0.0

    async def __aenter__(self) -> HorseProducer:
        """Connect; a first connection that fails raises :class:`ServiceUnreachable` (no retrying)."""
        try:
            async with asyncio.timeout(self.open_timeout):
                await self._connect()
        except (InvalidURI, ValueError, KeyError, *_RETRYABLE) as exc:
            raise _unreachable(self.url.removesuffix("/ws/horse"), exc, self.open_timeout) from None
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        await self.close()

    async def _connect(self) -> None:
        ws = await connect(self.url, subprotocols=_subprotocols(self.token), open_timeout=self.open_timeout)
        self.welcome = json.loads(await ws.recv())
        await ws.send(json.dumps(self.hello))
        self._ws = ws
        self._backoff.reset()
        self._reader = asyncio.get_running_loop().create_task(self._read(ws))

    async def _read(self, ws: ClientConnection) -> None:
        try:
            async for message in ws:
                obj = json.loads(message)
                if obj.get("type") == "control":
                    self.driving = obj["driving"]
                elif obj.get("type") == "error":
                    self.errors.append(obj)
                    log.warning("server rejected a frame: %s", obj.get("message"))
        except ConnectionClosed:
            pass

    async def send(self, t: float, values: dict[str, float]) -> bool:
        """Send one frame (``t`` seconds, channel -> value); False if it could not go out."""
        loop = asyncio.get_running_loop()
        if self._ws is None:
            if loop.time() < self._retry_at:
                return False
            try:
                await self._connect()
            except _RETRYABLE:
                self._retry_at = loop.time() + self._backoff.next()
                return False
        assert self._ws is not None
        frame = {"t": t, "values": values}
        try:
            await self._ws.send(msgpack.packb(frame) if self.binary else json.dumps(frame))
        except ConnectionClosed:
            self._ws = None
            self.driving = None
            return False
        return True

    async def close(self) -> None:
        if self._ws is not None:
            await self._ws.close()
            self._ws = None
        if self._reader is not None:
            self._reader.cancel()
