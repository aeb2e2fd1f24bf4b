"""The service's timecode: which SMPTE label each tick record carries (docs/timecode.md).

Three sources, first one that applies:

1. **producer**: the driving producer sent ``tc`` on its frames (``/ws/horse``, NATS):
   the record's label is the producer's label at the record's ``source_t`` (its anchor
   runs at the rate's real fps from the producer's last label). A replay is a producer
   whose labels are the take's own (its sidecar's start timecode).
2. **stage**: a stage heartbeat carrying ``tc`` arrived within ``timecode.stage_timeout``:
   the stage's label at the record's engine time (every rig on the stage agrees).
3. **host**: the host clock's time of day plus ``timecode.offset``.

Only :func:`host_timecode` reads a clock (once, at start: the wall-clock time of engine
time 0 and the time zone's offset); the rest is pure. Errors are counted in ``counts`` (metrics label: reason).
"""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass
from enum import StrEnum
from typing import TYPE_CHECKING, Any

import numpy as np

from riderlive import timecode as tc
from riderlive.realtime.core import Driver
from riderlive.realtime.record import RecordLayout
from riderlive.timecode import RATES, Anchor, Rate, TimecodeError

if TYPE_CHECKING:
    from riderlive.service.config import TimecodeSection


class Source(StrEnum):
    PRODUCER = "producer"
    STAGE = "stage"
    HOST = "host"


@dataclass(frozen=True)
class Stamp:
    """A record's timecode: frames since 00:00:00:00 at ``rate``, and where it came from."""

    frames: int
    rate: Rate
    source: Source

    @property
    def label(self) -> str:
        return tc.format_frames(self.frames, self.rate)

    def as_meta(self) -> dict[str, Any]:
        """The take sidecar's fields."""
        return {"timecode": self.label, "timecode_rate": self.rate.value, "timecode_source": self.source.value}


class ServiceTimecode:
    """Producer, stage and host timecode anchors of one service."""

    def __init__(
        self,
        rate: Rate,
        offset: float,
        stage_timeout: float,
        wall_at_engine_zero: float,
        counts: Counter[str] | None = None,
    ) -> None:
        """``wall_at_engine_zero``: seconds since local (or UTC) midnight of some day at engine time 0,
        the zone's offset included; ``offset``: seconds added (``timecode.offset``); ``counts``:
        where errors are counted (the service's metrics)."""
        self.rate = rate
        self.stage_timeout = stage_timeout
        day = RATES[rate].frames_per_day / RATES[rate].fps
        self.host = Anchor(t=-((wall_at_engine_zero + offset) % float(day)), frames=0, rate=rate)
        """Midnight (label 0) on the engine clock."""
        self.streams: dict[int, Anchor] = {}
        """Producer stream id -> its last label on the producer's clock."""
        self.stage: Anchor | None = None
        """The stage heartbeat's last label on the engine clock."""
        self.stage_seen = -1e9
        self.counts: Counter[str] = Counter() if counts is None else counts
        self.epoch_at_engine_zero = 0.0
        """Unix time of engine time 0 (for log times of Foxglove and MCAP messages)."""

    def parse_label(self, label: object, rate: object = None) -> int:
        """A wire ``tc`` (and optional ``tc_rate``) -> frames; TimecodeError (counted) otherwise."""
        try:
            if rate is not None and tc.parse_rate(rate) is not self.rate:
                raise TimecodeError(
                    "timecode_rate", f"tc_rate {rate!r} is not this service's timecode rate {self.rate.value}"
                )
            return tc.parse(label, self.rate)
        except TimecodeError as exc:
            self.counts[exc.reason] += 1
            raise

    def producer_label(self, stream: int, t: float, label: object, rate: object = None) -> int | None:
        """A producer's ``tc`` on its frame at producer time ``t``; returns the jump in frames
        against its previous label (counted) or None. TimecodeError: the label is unusable
        (the stream keeps its previous anchor)."""
        frames = self.parse_label(label, rate)
        previous = self.streams.get(stream)
        if previous is None:
            self.streams[stream] = Anchor(t, frames, self.rate)
            return None
        self.streams[stream], jump = tc.observe(previous, t, frames)
        if jump is not None:
            self.counts["timecode_jump"] += 1
        return jump

    def replay(self, stream: int, t0: float, frames: int) -> None:
        """A replay's stream: label ``frames`` at its first frame's time ``t0``."""
        self.streams[stream] = Anchor(t0, frames, self.rate)

    def forget(self, stream: int) -> None:
        self.streams.pop(stream, None)

    def stage_beat(self, engine_t: float, label: object, rate: object = None) -> None:
        """A stage heartbeat's ``tc`` received at ``engine_t``; TimecodeError (counted) when unusable."""
        frames = self.parse_label(label, rate)
        if self.stage is not None and engine_t - self.stage_seen <= self.stage_timeout:
            jump = tc.frames_between(frames, self.stage.frames_at(engine_t), self.rate)
            if abs(jump) > tc.JUMP_TOLERANCE_FRAMES + 2:  # the heartbeat's network delay: a few ms
                self.counts["stage_timecode_jump"] += 1
        self.stage = Anchor(engine_t, frames, self.rate)
        self.stage_seen = engine_t

    def at(self, engine_t: float, source_t: float, driver: int, stream: int) -> Stamp:
        """The timecode of one tick record."""
        if driver == Driver.INPUT:
            anchor = self.streams.get(stream)
            if anchor is not None:
                return Stamp(anchor.frames_at(source_t), self.rate, Source.PRODUCER)
        if self.stage is not None and engine_t - self.stage_seen <= self.stage_timeout:
            return Stamp(self.stage.frames_at(engine_t), self.rate, Source.STAGE)
        return Stamp(self.host.frames_at(engine_t), self.rate, Source.HOST)

    def of_record(self, record: np.ndarray) -> Stamp:
        return self.at(
            RecordLayout.engine_t.at(record),
            RecordLayout.source_t.at(record),
            RecordLayout.driver.count(record),
            RecordLayout.producer.count(record),
        )

    def wall_ns(self, engine_t: float) -> int:
        """Unix nanoseconds of engine time ``engine_t``."""
        return round((self.epoch_at_engine_zero + engine_t) * 1e9)

    def status(self, engine_t: float) -> dict[str, Any]:
        """For ``/api/state`` and the page: the host-or-stage label now, the rate, the counters."""
        stamp = self.at(engine_t, engine_t, -1, 0)
        return {"rate": self.rate.value, "tc": stamp.label, "source": stamp.source.value, "errors": dict(self.counts)}


def host_timecode(section: TimecodeSection, engine_start: float, counts: Counter[str]) -> ServiceTimecode:
    """The service's timecode for ``[timecode]`` (the edge: reads the host clock and time zone once;
    ``engine_start``: the ``perf_counter`` of engine time 0). A change of daylight saving time
    during a run is not followed (restart the service)."""
    wall = time.time() - (time.perf_counter() - engine_start)
    zone = time.localtime(wall).tm_gmtoff if section.clock == "local" else 0
    out = ServiceTimecode(section.rate, section.offset, section.stage_timeout, (wall + zone) % 86400.0, counts)
    out.epoch_at_engine_zero = wall
    return out


def host_label(rate: Rate, offset: float = 0.0, clock: str = "local", wall: float | None = None) -> str:
    """The host clock's label now (or at Unix time ``wall``): ``riderlive stage heartbeat``'s ``tc``."""
    wall = time.time() if wall is None else wall
    zone = time.localtime(wall).tm_gmtoff if clock == "local" else 0
    return tc.format_frames(tc.seconds_to_frames((wall + zone + offset) % 86400.0, rate), rate)
