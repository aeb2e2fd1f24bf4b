"""The interface between riderlive and a messaging engine (NATS today).

A transport moves opaque byte payloads on dotted subjects: publish, subscribe with a
callback, request/reply with a timeout, and reports its connection events. Everything
riderlive-specific (subjects, encodings, validation, safety) lives above it, so another
engine (Zenoh, MQTT: ``shared/spec/facts.md`` compares them) needs one module that
implements this protocol, nothing else.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Protocol


@dataclass(frozen=True)
class Message:
    """One received message: its subject, payload and reply subject ("" when none)."""

    subject: str
    data: bytes
    reply: str = ""


Handler = Callable[[Message], Awaitable[None]]


class TransportError(Exception):
    """A transport that cannot do what was asked; the message says why."""


class Refused(TransportError):
    """The broker refused our credentials (or the TLS handshake)."""


class Unreachable(TransportError):
    """No broker answered at the given address(es)."""


class NoResponders(TransportError):
    """A request found nobody subscribed to its subject."""


@dataclass
class TransportStats:
    """Connection events, counted (``riderlive_nats_events_total`` in ``/metrics``)."""

    events: Counter[str] = field(default_factory=Counter)
    """disconnects, reconnects, errors, slow_consumer, auth_refused..."""
    connected: bool = False


class Subscription(Protocol):
    async def unsubscribe(self) -> None: ...


class Transport(Protocol):
    """What riderlive needs from a messaging engine."""

    stats: TransportStats

    @property
    def connected(self) -> bool: ...

    async def publish(self, subject: str, data: bytes, reply: str = "") -> None:
        """Queue ``data`` for ``subject``; never waits on subscribers."""

    async def subscribe(self, subject: str, handler: Handler, pending_limit: int = 4096) -> Subscription:
        """Call ``handler`` for each message on ``subject`` (wildcards ``*`` and ``>``).

        More than ``pending_limit`` messages waiting for the handler: the newest are
        dropped and counted (``slow_consumer``)."""

    async def request(self, subject: str, data: bytes, timeout: float) -> bytes:
        """One reply to ``data``: :class:`NoResponders`, or TimeoutError after ``timeout`` s."""

    def new_inbox(self) -> str:
        """A unique subject for replies addressed to this connection."""

    async def flush(self, timeout: float = 2.0) -> None:
        """Until the broker has everything published so far."""

    async def close(self) -> None: ...
