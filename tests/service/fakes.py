"""Fakes of the service's ports (riderlive/service/ports.py) for in-process tests.

:class:`FakeTick` records what the web side hands the tick and answers from a clock the
test sets (``clock.now``, ``perf_counter``-like seconds); :class:`FakeService` is the
rest of what an endpoint reads: the real configuration, metrics, arbiter and poses.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from riderlive.channels import RIDER_PART_NAMES
from riderlive.devices.latch import StopSource
from riderlive.realtime import commands as cmd
from riderlive.realtime.layout import InputKind
from riderlive.service.arbiter import Arbiter
from riderlive.service.config import ServiceConfig
from riderlive.service.devices_api import DeviceMetrics
from riderlive.service.metrics import ServiceMetrics
from riderlive.service.poses import RecordPoses
from riderlive.service.timecodes import host_timecode


@dataclass
class Clock:
    now: float = 1000.0

    def advance(self, seconds: float) -> float:
        self.now += seconds
        return self.now


@dataclass
class Pushed:
    producer: int
    t: float
    received: float
    values: list[float]
    kind: InputKind
    rebased: bool = False


@dataclass
class FakeTick:
    """A :class:`~riderlive.service.ports.TickPort`: engine time is ``clock.now - start``."""

    clock: Clock
    start_at: float = 1000.0
    up: bool = True
    pushed: list[Pushed] = field(default_factory=list)
    told: list[cmd.Command] = field(default_factory=list)
    tick_status: dict[str, Any] = field(default_factory=dict)

    @property
    def start(self) -> float:
        return self.start_at

    def engine_time(self) -> float:
        return self.clock.now - self.start_at

    def push_input(
        self,
        producer: int,
        t: float,
        received: float,
        values: list[float] | np.ndarray,
        kind: InputKind = InputKind.HORSE,
        *,
        rebased: bool = False,
    ) -> None:
        self.pushed.append(Pushed(producer, t, received, list(values), kind, rebased))

    def input_pending(self, received: float | None) -> None:
        """Nothing waits on it here (the real tick's pickup does)."""

    def tell(self, command: cmd.Command) -> bool:
        if self.up:
            self.told.append(command)
        return self.up

    def status(self) -> dict[str, Any]:
        return self.tick_status


@dataclass
class FakeStops:
    """A :class:`~riderlive.service.ports.StopPort` that counts requests."""

    clock: Clock
    requests: list[StopSource] = field(default_factory=list)

    def estop(self, source: StopSource) -> float:
        self.requests.append(source)
        return self.clock.now


class FakeService:
    """An :class:`~riderlive.service.ports.IngestPort` and a :class:`~riderlive.service.ports.PublishPort`."""

    def __init__(self, config: ServiceConfig | None = None, clock: Clock | None = None) -> None:
        self.config = config or ServiceConfig()
        self.clock = clock or Clock()
        self.session = "test-session"
        self.metrics = ServiceMetrics()
        self.arbiter = Arbiter(self.config.input.producer_timeout)
        self.link = FakeTick(self.clock, start_at=self.clock.now)
        self.poses = RecordPoses(self.config.tick.length_scale)
        self.extra_channels: tuple[str, ...] = RIDER_PART_NAMES
        self.supervisor = FakeStops(self.clock)
        self.timecode = host_timecode(self.config.timecode, self.clock.now, self.metrics.timecode)
        self.device_metrics = DeviceMetrics()
