"""Who drives the tick: the producers of ``/ws/horse`` and ``/ws/saddle`` (and NATS, and the
replay) and the one arbiter that picks among them (pure: no socket, no clock of its own).

Arbitration (docs/protocol.md, "Several producers"), the same for both kinds: a saddle
producer and a horse producer compete exactly like two horse producers.

- Source ``live``: the driving producer is the one with the highest ``priority``
  (declared in its hello, default 0). Among equals the incumbent keeps control; a
  newcomer takes over only when the incumbent disconnects or sends nothing for
  ``input.producer_timeout`` seconds. A higher priority takes over at its next frame.
  Each change of driver is counted by its reason (:class:`Handover`) and the last one kept
  (``/api/state`` ``arbitration``, ``riderlive_arbiter_handovers_total``): a takeover by
  silence on a busy host says who fell silent and for how long.
- Source ``replay``: only the replay drives; live producers are on standby.
- Source ``procedural``: nobody drives; frames are validated and counted only.

Each producer is told ``{"type": "control", "driving": true|false}`` when that changes.

A producer's values are converted to the service's units and checked against their
plausible ranges (:meth:`Producer.convert`); its websocket endpoint is ``service/ingest.py``.
"""

from __future__ import annotations

import enum
import functools
import itertools
import math
from collections import Counter, deque
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any

from riderlive.channels import HORSE, HORSE_NAMES, SADDLE, Channel, Kind
from riderlive.realtime.layout import InputKind
from riderlive.service.clocks import ProducerClock
from riderlive.service.codecs import BadFrame

if TYPE_CHECKING:
    from starlette.websockets import WebSocket

_ids = itertools.count(1)


def next_producer_id() -> int:
    return next(_ids)


@dataclass(frozen=True)
class InputSpec:
    """What one input endpoint accepts."""

    kind: InputKind
    channels: tuple[Channel, ...]
    keep_last: bool
    """An omitted channel keeps its last value (horse) or is missing for that frame (saddle: NaN)."""
    prefix: str
    """Default producer names: ``<prefix>-<id>``."""

    @functools.cached_property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.channels)

    @functools.cached_property
    def index(self) -> dict[str, int]:
        return {c.name: i for i, c in enumerate(self.channels)}

    @functools.cached_property
    def what(self) -> str:
        return self.kind.name.lower()

    @functools.cached_property
    def translations(self) -> frozenset[int]:
        return frozenset(i for i, c in enumerate(self.channels) if c.kind is Kind.TRANSLATION)


HORSE_INPUT = InputSpec(InputKind.HORSE, HORSE, keep_last=True, prefix="producer")
SADDLE_INPUT = InputSpec(InputKind.SADDLE, SADDLE, keep_last=False, prefix="saddle")


@dataclass
class Producer:
    """One connected producer (or the replay) and its per-connection settings."""

    id: int
    name: str
    priority: int = 0
    length_gain: float = 1.0
    """Producer length unit -> service length unit."""
    order: tuple[int, ...] | None = None
    spec: InputSpec = HORSE_INPUT
    last: list[float] = field(default_factory=lambda: [0.0] * len(HORSE_NAMES))
    last_frame_at: float = -1e9
    stream: int = 0
    """The id the tick knows this producer's current stream segment by (0: ``id``)."""
    segment: int = 0
    clock: ProducerClock = field(default_factory=ProducerClock)
    """Its clock in the current segment (service/clocks.py)."""
    outbox: list[dict[str, Any]] = field(default_factory=list)
    """Messages for the producer decided while handling a frame, sent right after."""
    accepted: int = 0
    rejected: int = 0
    errors: deque[float] = field(default_factory=deque)
    window_start: float = 0.0
    window_frames: int = 0
    websocket: WebSocket | None = None
    timecode_error_at: float = -1e9
    """When the producer was last told its ``tc`` is unusable (at most once a second)."""

    def __post_init__(self) -> None:
        self.stream = self.stream or self.id
        self._translations = self.spec.translations
        if len(self.last) != len(self.spec.channels):
            self.last = [0.0] * len(self.spec.channels)

    def convert(self, values: dict[int, float], low: list[float], high: list[float]) -> dict[int, float]:
        """A frame's values in service units, or :class:`BadFrame` for the first one outside its range."""
        gain = self.length_gain
        translations = self._translations
        out = {}
        for index, value in values.items():
            scaled = value * gain if gain != 1.0 and index in translations else value
            if not low[index] <= scaled <= high[index]:
                unit = gain if index in translations else 1.0
                raise BadFrame(
                    "out_of_range",
                    f"{self.spec.channels[index].name} = {value!r} is outside its plausible range "
                    f"[{low[index] / unit:g}, {high[index] / unit:g}] (docs/protocol.md, ranges)",
                )
            out[index] = scaled
        return out

    def merge(self, values: dict[int, float]) -> list[float]:
        """Apply converted values onto the last frame (omitted channels keep their last value),
        or, for an input whose omitted channels are missing, fill the gaps with NaN."""
        if not self.spec.keep_last:
            out = [math.nan] * len(self.spec.channels)
            for index, value in values.items():
                out[index] = value
            return out
        for index, value in values.items():
            self.last[index] = value
        return list(self.last)


class Handover(enum.StrEnum):
    """Why a live producer began to drive."""

    VACANT = "vacant"
    """Nobody drove: the first producer, or the driver left."""
    PRIORITY = "priority"
    """Its priority is higher than the driver's."""
    SILENCE = "silence"
    """The driver, of the same or a higher priority, sent nothing for ``input.producer_timeout``."""


@dataclass(frozen=True)
class HandoverEvent:
    """One change of driver (the producers' names as they gave them)."""

    to: str
    reason: Handover
    previous: str | None = None
    """The driver it took over from (None: nobody drove)."""
    silent_for: float | None = None
    """How long that driver had sent nothing (s; None unless ``reason`` is silence)."""

    def as_dict(self) -> dict[str, Any]:
        return {**asdict(self), "reason": self.reason.value}


class Arbiter:
    """Which producer drives; see the module docstring."""

    def __init__(self, timeout: float) -> None:
        self.timeout = timeout
        self.producers: dict[int, Producer] = {}
        self.active: int | None = None
        self.selection: str = "live"
        self.replay_id: int | None = None
        self.handovers: Counter[Handover] = Counter()
        """Changes of driver in source ``live``, by reason."""
        self.last_handover: HandoverEvent | None = None

    def drives(self, producer: Producer, now: float) -> bool:
        """Called for each accepted frame; True when this producer's frame goes to the tick."""
        if self.selection == "procedural":
            return False
        if self.selection == "replay":
            return producer.id == self.replay_id
        current = self.producers.get(self.active) if self.active is not None else None
        if current is producer:
            return True
        if current is None:
            event = HandoverEvent(producer.name, Handover.VACANT)
        elif producer.priority > current.priority:
            event = HandoverEvent(producer.name, Handover.PRIORITY, current.name)
        elif (silent := now - current.last_frame_at) > self.timeout:
            event = HandoverEvent(producer.name, Handover.SILENCE, current.name, silent)
        else:
            return False
        self.active = producer.id
        self.handovers[event.reason] += 1
        self.last_handover = event
        return True

    def handover_counts(self) -> dict[str, int]:
        """Changes of driver by reason, every reason named (``/api/state``, ``/metrics``)."""
        return {reason.value: self.handovers[reason] for reason in Handover}

    def status(self) -> dict[str, Any]:
        """``/api/state``'s ``arbitration``: the selection, the driver, each producer, the handovers."""
        return {
            "selection": self.selection,
            "active": self.active,
            "producers": [
                {
                    "id": p.id,
                    "name": p.name,
                    "kind": p.spec.what,
                    "priority": p.priority,
                    "accepted": p.accepted,
                    "rejected": p.rejected,
                }
                for p in self.producers.values()
            ],
            "handovers": self.handover_counts(),
            "last_handover": None if self.last_handover is None else self.last_handover.as_dict(),
        }

    def remove(self, producer_id: int) -> bool:
        """Forget a producer; True if it was driving."""
        self.producers.pop(producer_id, None)
        was_active = self.active == producer_id or (self.selection == "replay" and self.replay_id == producer_id)
        if self.active == producer_id:
            self.active = None
        return was_active
