"""The NATS implementation of :class:`~riderlive.bus.transport.Transport` (``nats-py``).

Connection policy: :func:`connect` first tries once without retrying, bounded by
``connect_timeout`` s (+ 1 s of slack as a whole: a closed port, a host that drops
packets, a port that accepts and never speaks NATS), so a wrong address or refused credentials is a clear error
at start (:class:`Unreachable`, :class:`Refused`). nats-py alone does not bound it: its
first connect walks the server pool ``max_reconnect_attempts`` times even with
``allow_reconnect=False`` (and forever with 0). The connection it then keeps reconnects
forever (every ``reconnect_wait`` s) across broker restarts and cut cables. Messages published while
disconnected are *not* buffered for later (:meth:`NatsTransport.publish` drops them,
counted ``dropped_disconnected``): a live frame from two seconds ago is worse than none,
and an e-stop is re-sent by whoever means it.
"""

from __future__ import annotations

import asyncio
import contextlib
import ssl
from dataclasses import dataclass
from typing import Any

import nats
import nats.errors
from nats.aio.client import Client
from nats.aio.msg import Msg

from riderlive.bus.transport import (
    Handler,
    Message,
    NoResponders,
    Refused,
    Subscription,
    TransportError,
    TransportStats,
    Unreachable,
)


@dataclass(frozen=True)
class Credentials:
    """How to authenticate to the broker and protect the link (all optional)."""

    user: str | None = None
    password: str | None = None
    token: str | None = None
    creds: str | None = None
    """A ``.creds`` file (JWT + nkey seed, NATS decentralised auth)."""
    tls_ca: str | None = None
    tls_cert: str | None = None
    tls_key: str | None = None

    def options(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        if self.user is not None:
            out["user"] = self.user
            out["password"] = self.password or ""
        if self.token is not None:
            out["token"] = self.token
        if self.creds is not None:
            out["user_credentials"] = self.creds
        if self.tls_ca or self.tls_cert:
            context = ssl.create_default_context(cafile=self.tls_ca)
            if self.tls_cert:
                context.load_cert_chain(self.tls_cert, self.tls_key)
            out["tls"] = context
        return out


def _refusal(exc: BaseException) -> bool:
    text = str(exc).lower()
    return isinstance(exc, nats.errors.AuthorizationError) or "authorization" in text or "authentication" in text


class NatsTransport:
    """One NATS connection; see the module docstring for the policy."""

    def __init__(self, client: Client, stats: TransportStats) -> None:
        self.client = client
        self.stats = stats

    @property
    def connected(self) -> bool:
        return bool(self.client.is_connected)

    async def publish(self, subject: str, data: bytes, reply: str = "") -> None:
        if not self.client.is_connected:
            self.stats.events["dropped_disconnected"] += 1
            return
        try:
            await self.client.publish(subject, data, reply=reply)
        except (nats.errors.ConnectionClosedError, nats.errors.OutboundBufferLimitError, OSError):
            self.stats.events["publish_errors"] += 1

    async def subscribe(self, subject: str, handler: Handler, pending_limit: int = 4096) -> Subscription:
        async def deliver(msg: Msg) -> None:
            await handler(Message(msg.subject, msg.data, msg.reply or ""))

        sub: Subscription = await self.client.subscribe(subject, cb=deliver, pending_msgs_limit=pending_limit)
        return sub

    async def request(self, subject: str, data: bytes, timeout: float) -> bytes:
        try:
            msg = await self.client.request(subject, data, timeout=timeout)
        except nats.errors.NoRespondersError:
            raise NoResponders(f"nobody listens on {subject}") from None
        except nats.errors.TimeoutError:
            raise TimeoutError(f"no reply on {subject} within {timeout:g} s") from None
        return bytes(msg.data)

    def new_inbox(self) -> str:
        return str(self.client.new_inbox())

    async def flush(self, timeout: float = 2.0) -> None:
        try:
            await self.client.flush(timeout=timeout)  # type: ignore[arg-type]  # seconds, any number
        except (nats.errors.TimeoutError, nats.errors.ConnectionClosedError) as exc:
            raise TransportError(f"flush failed: {exc!r}") from None

    async def close(self) -> None:
        if not self.client.is_closed:
            await self.client.close()
        self.stats.connected = False


def _what(exc: BaseException) -> str:
    if isinstance(exc, TimeoutError):
        return "no answer in time"
    return str(exc) or type(exc).__name__


SLACK_S = 1.0
"""Beyond ``connect_timeout`` for a whole first connect: nats-py bounds each of its steps
(TCP connect, the greeting, the PONG) by ``connect_timeout`` itself, so a closed port or a
mute broker ends at that; the slack keeps a busy host's slow handshake from failing."""


async def _bounded(client: Client, timeout: float, **options: Any) -> None:
    """``client.connect(**options)`` within ``timeout`` + :data:`SLACK_S` s, or closed and
    :class:`TimeoutError`."""
    try:
        await asyncio.wait_for(client.connect(**options), timeout + SLACK_S)
    except BaseException:
        with contextlib.suppress(Exception):
            await client.close()
        raise


async def _first_connect(url: str, servers: list[str], name: str, timeout: float, options: dict[str, Any]) -> Client:
    """One pass over the servers, no retry, within ``timeout`` s: the check that the broker is there.

    ``max_reconnect_attempts=1`` is the smallest that ends nats-py's server walk (0 means
    forever); the :func:`asyncio.wait_for` bounds the whole, including a port that accepts
    and never sends the NATS greeting."""
    client, seen = Client(), []

    async def keep(exc: Exception) -> None:
        """The first connect's errors are raised to us (nats-py would also print them)."""
        seen.append(exc)

    try:
        await _bounded(
            client,
            timeout,
            servers=servers,
            name=name,
            allow_reconnect=False,
            max_reconnect_attempts=1,
            reconnect_time_wait=0.0,
            connect_timeout=timeout,
            error_cb=keep,
            **options,
        )
    except Exception as exc:
        cause = seen[0] if seen and not isinstance(exc, TimeoutError) else exc  # the first, not "no servers"
        if _refusal(exc) or any(map(_refusal, seen)):
            raise Refused(f"the NATS server at {url} refused our credentials: {_what(cause)}") from None
        raise Unreachable(f"no NATS server answers at {url} within {timeout:g} s: {_what(cause)}") from None
    return client


async def connect(
    url: str,
    credentials: Credentials = Credentials(),
    name: str = "riderlive",
    *,
    connect_timeout: float = 2.0,
    reconnect_wait: float = 0.25,
    ping_interval: float = 1.0,
) -> NatsTransport:
    """A connection to the broker(s) at ``url`` (comma-separated for a cluster).

    :class:`Unreachable` or :class:`Refused` when the first attempt fails; after that
    the connection reconnects on its own. ``ping_interval`` (s): how soon a silently cut
    link is noticed (two unanswered pings)."""
    servers = [s.strip() for s in url.split(",") if s.strip()]
    options = credentials.options()
    probe = await _first_connect(url, servers, name, connect_timeout, options)
    await probe.close()
    stats = TransportStats()

    async def on_error(exc: Exception) -> None:
        if isinstance(exc, nats.errors.SlowConsumerError):
            stats.events["slow_consumer"] += 1
        elif _refusal(exc):
            stats.events["auth_refused"] += 1
        else:
            stats.events["errors"] += 1

    async def on_disconnect() -> None:
        stats.connected = False
        stats.events["disconnects"] += 1

    async def on_reconnect() -> None:
        stats.connected = True
        stats.events["reconnects"] += 1

    client = Client()
    try:
        await _bounded(
            client,
            connect_timeout,
            servers=servers,
            name=name,
            allow_reconnect=True,
            max_reconnect_attempts=-1,
            reconnect_time_wait=reconnect_wait,
            connect_timeout=connect_timeout,
            ping_interval=ping_interval,
            max_outstanding_pings=2,
            error_cb=on_error,
            disconnected_cb=on_disconnect,
            reconnected_cb=on_reconnect,
            **options,
        )
    except Exception as exc:
        raise Unreachable(f"lost the NATS server at {url} while connecting: {_what(exc)}") from None
    stats.connected = True
    return NatsTransport(client, stats)


def credentials_of(section: Any) -> Credentials:
    """The credentials of a ``[nats]`` section (:class:`riderlive.bus.config.NatsSection`)."""
    return Credentials(
        user=section.user,
        password=section.password,
        token=section.token,
        creds=section.creds,
        tls_ca=section.tls_ca,
        tls_cert=section.tls_cert,
        tls_key=section.tls_key,
    )
