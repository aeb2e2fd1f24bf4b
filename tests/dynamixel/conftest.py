"""Shared fixtures: an emulated Dynamixel bus on a pty and the real SDK opened on it.

    def test_something(bus, sdk):            # servos 1 XL430, 2 XM430, 3 XL330 at 1 Mbps
        model, result, error = sdk.ph.ping(sdk.port, 1)

    def test_big_rig(bus_factory):           # any servos and options
        bus = bus_factory(rider_servos(24), wire_timing=True)
        link = open_sdk(bus)

The emulator thread shares the GIL with the SDK's busy-polling reads, so the fixtures
lower the interpreter's switch interval while a bus runs (otherwise each reply can wait
one 5 ms switch interval). They also raise the SDK's reply timeout from 34 ms to
~200 ms (its module constant ``LATENCY_TIMER``, as for a slow USB adapter): on a loaded
2-core machine a thread can stall for more than 34 ms (100 ms seen), which would fail a test at random.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any

import pytest
from dynamixel_sdk import PacketHandler, PortHandler, port_handler

from riderlive.dynamixel.emulator import EmulatedBus, ServoSetup

FAST_BAUD = 4_000_000
"""Baud for tests that do not measure timing (every model here supports it)."""
DEFAULT_SERVOS = (ServoSetup(1, "XL430-W250"), ServoSetup(2, "XM430-W350"), ServoSetup(3, "XL330-M288"))
MODELS_CYCLE = ("XM430-W350", "XL430-W250", "XL330-M288")


def rider_servos(count: int = 24) -> list[ServoSetup]:
    """``count`` servos with ids 1..count, cycling through the supported models."""
    return [ServoSetup(i, MODELS_CYCLE[(i - 1) % len(MODELS_CYCLE)]) for i in range(1, count + 1)]


class ManualClock:
    """A clock for the emulator that moves only when the test says: watchdog, motion and
    thermal timing become exact, whatever the machine's load. Starts at 1000 s."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now

    def advance(self, seconds: float) -> None:
        self.now += seconds


@dataclass
class SdkLink:
    """The unmodified SDK's port and Protocol 2.0 packet handler, open on a bus."""

    port: Any
    ph: Any

    def close(self) -> None:
        if self.port.is_open:
            self.port.closePort()


def open_sdk(bus: EmulatedBus) -> SdkLink:
    port = PortHandler(bus.port)
    assert port.openPort(), f"the SDK could not open {bus.port}"
    assert port.setBaudRate(bus.baud)
    return SdkLink(port, PacketHandler(2.0))


SDK_LATENCY_TIMER_MS = 100
"""Patched into ``dynamixel_sdk.port_handler.LATENCY_TIMER``: reply timeout 2 x 100 + 2 ms."""


@pytest.fixture
def fast_switching(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    previous = sys.getswitchinterval()
    sys.setswitchinterval(0.0002)
    monkeypatch.setattr(port_handler, "LATENCY_TIMER", SDK_LATENCY_TIMER_MS)
    yield
    sys.setswitchinterval(previous)


@pytest.fixture
def bus_factory(fast_switching: None) -> Iterator[Callable[..., EmulatedBus]]:
    """Start buses of given servos (keyword options as EmulatedBus); all stop at teardown."""
    buses: list[EmulatedBus] = []

    def make(servos: Iterable[ServoSetup] = DEFAULT_SERVOS, **options: Any) -> EmulatedBus:
        options.setdefault("baud", FAST_BAUD)
        bus = EmulatedBus(servos, **options).start()
        buses.append(bus)
        return bus

    yield make
    for bus in buses:
        bus.stop()


@pytest.fixture
def bus(bus_factory: Callable[..., EmulatedBus]) -> EmulatedBus:
    """Servos 1 (XL430-W250), 2 (XM430-W350), 3 (XL330-M288) at 4 Mbps, no wire timing."""
    return bus_factory()


@pytest.fixture
def clock() -> ManualClock:
    return ManualClock()


@pytest.fixture
def timed_bus(bus_factory: Callable[..., EmulatedBus], clock: ManualClock) -> EmulatedBus:
    """Like ``bus``, but on the test's :class:`ManualClock` (the ``clock`` fixture)."""
    return bus_factory(clock=clock)


@pytest.fixture
def timed_sdk(timed_bus: EmulatedBus) -> Iterator[SdkLink]:
    link = open_sdk(timed_bus)
    yield link
    link.close()


@pytest.fixture
def sdk(bus: EmulatedBus) -> Iterator[SdkLink]:
    link = open_sdk(bus)
    yield link
    link.close()
