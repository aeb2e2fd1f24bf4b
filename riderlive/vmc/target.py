"""A VMC target as configured: ``HOST:PORT`` checked (pure; below the service configuration that validates it)."""

from __future__ import annotations

DEFAULT_PORT = 39539
"""The marionettes' usual port."""


class VmcError(ValueError):
    """A VMC target or local port that cannot be used; the message names it."""


def parse_target(text: str, what: str = "VMC target") -> tuple[str, int]:
    """``HOST:PORT`` (``[v6]:PORT`` for IPv6 literals) -> (host, port)."""
    host, sep, port_text = text.rpartition(":")
    if not sep or not host or not port_text.isdigit() or not 1 <= int(port_text) <= 65535:
        raise VmcError(f"{what} {text!r}: expected HOST:PORT with a port 1..65535 (e.g. 127.0.0.1:{DEFAULT_PORT})")
    return host.removeprefix("[").removesuffix("]"), int(port_text)
