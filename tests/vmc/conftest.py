"""Fixtures shared by the VMC tests."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest


@pytest.fixture
def receivers() -> Iterator[tuple[Any, Any]]:
    """A rider and a horse VMC receiver (python-osc servers on loopback UDP), closed after."""
    pytest.importorskip("pythonosc")
    from tests.vmc.receiver import VmcReceiver

    rider, horse = VmcReceiver(), VmcReceiver()
    yield rider, horse
    rider.close()
    horse.close()
