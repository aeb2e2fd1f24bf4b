"""Tokens for ingest and control, compared in constant time, never in a URL.

A websocket client sends the token as a subprotocol ``riderlive.token.<TOKEN>`` beside
``riderlive.v1`` (browsers can set subprotocols, not headers), or as ``"token"`` in
its first message. REST clients send ``Authorization: Bearer <TOKEN>``. None of these
reach uvicorn's access log, which prints only the path and query string.

Every REST write (POST, PUT, PATCH, DELETE) is checked by one ASGI middleware,
:class:`WriteGuard`, before the route is even looked up: a request without the token
gets 401 before its body is read, parsed or validated, and a route added later is
covered without a word (the default rule is :attr:`Rule.CONTROL`). :data:`WRITE_RULES`
is the table of the writes that differ or are counted by action.
"""

from __future__ import annotations

import enum
import hmac
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import orjson
from starlette.types import ASGIApp, Receive, Scope, Send

SUBPROTOCOL = "riderlive.v1"
TOKEN_PREFIX = "riderlive.token."


class Unauthorized(Exception):
    """Missing or wrong token."""


def token_matches(expected: str | None, given: object) -> bool:
    if expected is None or not isinstance(given, str):
        return False
    return hmac.compare_digest(expected.encode(), given.encode())


def token_from_subprotocols(offered: list[str]) -> str | None:
    for proto in offered:
        if proto.startswith(TOKEN_PREFIX):
            return proto[len(TOKEN_PREFIX) :]
    return None


def accepted_subprotocol(offered: list[str]) -> str | None:
    """The subprotocol to answer with: ours if offered (never the token)."""
    return SUBPROTOCOL if SUBPROTOCOL in offered else None


def bearer(header: str | None) -> str | None:
    if header and header.lower().startswith("bearer "):
        return header[7:].strip()
    return None


UNAUTHORIZED = "unauthorized"
"""The refusal reason of a 401 (``riderlive.devices.lifecycle.Refusal.UNAUTHORIZED``)."""
TOKEN_REQUIRED = "token required: Authorization: Bearer <token>"
WRITE_METHODS = frozenset({"POST", "PUT", "PATCH", "DELETE"})


class Rule(enum.Enum):
    """When a write needs the token."""

    CONTROL = "control"
    """When the service requires one: bound beyond loopback, or ``security.require_token``."""
    ARMING = "arming"
    """Whenever one is configured, loopback too: the request makes hardware move (or may)."""


@dataclass(frozen=True)
class WriteRule:
    rule: Rule
    action: str | None = None
    """The action a refusal is counted under (``riderlive_device_refusals_total``), if any."""


DEFAULT_WRITE = WriteRule(Rule.CONTROL)
"""Every write not in :data:`WRITE_RULES` (source, preset, params, animator, record, bake...)."""
WRITE_RULES: Mapping[tuple[str, str], WriteRule] = {
    ("POST", "/api/arm"): WriteRule(Rule.ARMING, "arm"),
    ("POST", "/api/reset"): WriteRule(Rule.ARMING, "reset"),
    ("POST", "/api/reload"): WriteRule(Rule.ARMING, "reload"),
    ("PATCH", "/api/platform"): WriteRule(Rule.ARMING, "tune"),
    ("POST", "/api/disarm"): WriteRule(Rule.CONTROL, "disarm"),
    # A stop follows the other control calls: off loopback it needs the token (docs/api.md).
    ("POST", "/api/estop"): WriteRule(Rule.CONTROL, "estop"),
}


def write_rule(method: str, path: str) -> WriteRule | None:
    """The rule of a request, None for a read (GET, HEAD, OPTIONS)."""
    if method.upper() not in WRITE_METHODS:
        return None
    return WRITE_RULES.get((method.upper(), path.rstrip("/") or "/"), DEFAULT_WRITE)


class WriteGuard:
    """ASGI middleware: every write without the token it needs answers 401 before its body is read.

    ``token``: ``security.token`` (None: none configured); ``required``: the service requires
    it for :attr:`Rule.CONTROL` writes; ``refused(action)`` counts a refusal (action None:
    a write without a per-action counter)."""

    def __init__(self, app: ASGIApp, token: str | None, required: bool, refused: Callable[[str | None], None]) -> None:
        self.app = app
        self.token = token
        self.required = required
        self.refused = refused

    def needs_token(self, rule: WriteRule) -> bool:
        return self.token is not None if rule.rule is Rule.ARMING else self.required

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http":
            rule = write_rule(scope["method"], scope["path"])
            if rule is not None and self.needs_token(rule):
                headers = dict(scope.get("headers", ()))
                given = bearer(headers.get(b"authorization", b"").decode("latin-1"))
                if not token_matches(self.token, given):
                    self.refused(rule.action)
                    await _unauthorized(send)
                    return
        await self.app(scope, receive, send)


async def _unauthorized(send: Send) -> None:
    body = orjson.dumps({"detail": {"refusal": UNAUTHORIZED, "message": TOKEN_REQUIRED}})
    headers = [
        (b"content-type", b"application/json"),
        (b"content-length", str(len(body)).encode()),
        (b"www-authenticate", b"Bearer"),
    ]
    await send({"type": "http.response.start", "status": 401, "headers": headers})
    await send({"type": "http.response.body", "body": body})
