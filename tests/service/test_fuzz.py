"""A small run of ``bench/fuzz_service.py``'s generator against the real server (the bench sends 10^6)."""

from __future__ import annotations

import asyncio

from bench.fuzz_service import Hostile, fuzz, verdict
from tests.service.live_server import LiveServer


def test_the_generator_is_hostile_in_every_way() -> None:
    generator = Hostile(3)
    messages = [generator.message() for _ in range(3000)]
    channels = {channel for channel, _ in messages}
    assert channels == {"horse", "rider", "rest"}
    payloads = [m for c, m in messages if c == "horse"]
    assert any(isinstance(m, bytes) for m in payloads) and any(isinstance(m, str) for m in payloads)
    assert any(isinstance(m, str) and len(m) < 65536 < len(m.encode()) for m in payloads), "bytes, not characters"
    assert Hostile(3).message() == Hostile(3).message(), "seeded: a failure can be replayed"


def test_hostile_clients_cannot_crash_poison_or_freeze_the_service(server: LiveServer) -> None:
    result = asyncio.run(fuzz(server.base, server.ws, messages=1500, connections=3, seed=7))
    checks = verdict(result)
    assert all(checks.values()), (checks, result["reader"].problems[:5], result["rejects_seen"], result)
    assert result["sent"] >= 1450
    assert sum(result["rejects_seen"].values()) > 300, "most of it was rejected, and each reject counted"
    assert result["reader"].frames > 100, "the clean reader kept getting frames"
    assert server.proc.poll() is None
