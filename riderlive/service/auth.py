"""Tokens for ingest and control, compared in constant time, never in a URL.

A websocket client sends the token as a subprotocol ``riderlive.token.<TOKEN>`` beside
``riderlive.v1`` (browsers can set subprotocols, not headers), or as ``"token"`` in
its first message. REST clients send ``Authorization: Bearer <TOKEN>``. None of these
reach uvicorn's access log, which prints only the path and query string.
"""

from __future__ import annotations

import hmac

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
