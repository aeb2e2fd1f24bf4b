"""``/ws/horse`` and ``/ws/saddle``: producers stream horse frames or saddle samples in;
one arbiter picks the one that drives.

The two endpoints share everything (envelope, validation, auth, limits, error replies,
counters) but their channels (:class:`InputSpec`): ``channels.HORSE`` or the six
``channels.SADDLE``. On ``/ws/horse`` a channel a frame omits keeps its last value; on
``/ws/saddle`` it is *missing* for that sample (NaN to the estimator, which holds it).

Arbitration (docs/protocol.md, "Several producers"), the same for both kinds: a saddle
producer and a horse producer compete exactly like two horse producers.

- Source ``live``: the driving producer is the one with the highest ``priority``
  (declared in its hello, default 0). Among equals the incumbent keeps control; a
  newcomer takes over only when the incumbent disconnects or sends nothing for
  ``input.producer_timeout`` seconds. A higher priority takes over at its next frame.
- Source ``replay``: only the replay drives; live producers are on standby.
- Source ``procedural``: nobody drives; frames are validated and counted only.

Each producer is told ``{"type": "control", "driving": true|false}`` when that changes.

Every value is checked against its plausible range (:mod:`riderlive.ranges`) after
conversion to the service's units; a frame with one value outside is rejected whole.
A producer whose clock jumps, steps back, stands still or resumes
(:func:`~riderlive.service.clocks.clock_step`) starts a new *segment* and is told
``{"type": "segment", ...}`` (docs/protocol.md, "Clocks that jump"): after a jump the
tick sees a new stream id, re-anchors its clock mapping and blends; after a step back, a
pause (the service's clock stands in, so it keeps driving) or a resume, the time the
tick is given stays continuous in the same stream.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import itertools
import logging
import math
import time
from collections import deque
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from starlette.websockets import WebSocket, WebSocketDisconnect

from riderlive.channels import HORSE, HORSE_NAMES, SADDLE, Channel, Kind
from riderlive.ranges import Ranges
from riderlive.realtime import commands as cmd
from riderlive.realtime.layout import InputKind
from riderlive.service import auth
from riderlive.service.clocks import ClockStep, ProducerClock, clock_step
from riderlive.service.codecs import PROTOCOL_VERSION, BadFrame, channel_order, decode_frame, parse_message

if TYPE_CHECKING:
    from riderlive.service.runtime import Service

log = logging.getLogger(__name__)
_ids = itertools.count(1)
PAUSE_S = 0.1
"""A clock that stands still this long (or half ``input.hold``, if less) while frames
keep coming is paused: the service's clock stands in before the tick's hold runs out."""
LENGTH_SCALE_RANGE = (1e-6, 1e6)
"""Accepted ``length_scale`` of a producer's hello (thesis rig units per its length unit)."""


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


class Arbiter:
    """Which producer drives; see the module docstring."""

    def __init__(self, timeout: float) -> None:
        self.timeout = timeout
        self.producers: dict[int, Producer] = {}
        self.active: int | None = None
        self.selection: str = "live"
        self.replay_id: int | None = None

    def drives(self, producer: Producer, now: float) -> bool:
        """Called for each accepted frame; True when this producer's frame goes to the tick."""
        if self.selection == "procedural":
            return False
        if self.selection == "replay":
            return producer.id == self.replay_id
        current = self.producers.get(self.active) if self.active is not None else None
        if current is producer:
            return True
        if current is None or now - current.last_frame_at > self.timeout or producer.priority > current.priority:
            self.active = producer.id
            return True
        return False

    def remove(self, producer_id: int) -> bool:
        """Forget a producer; True if it was driving."""
        self.producers.pop(producer_id, None)
        was_active = self.active == producer_id or (self.selection == "replay" and self.replay_id == producer_id)
        if self.active == producer_id:
            self.active = None
        return was_active


async def send_quietly(websocket: WebSocket, message: dict[str, Any], timeout: float) -> None:
    """Send a JSON message; a client that does not read or has left is ignored."""
    with contextlib.suppress(Exception):  # gone or stuck: its receive loop will end it
        await asyncio.wait_for(websocket.send_json(message), timeout)


class IngestEndpoint:
    """The ``/ws/horse`` (or, with ``SADDLE_INPUT``, ``/ws/saddle``) handler, bound to the running service."""

    def __init__(self, service: Service, ranges: Ranges, spec: InputSpec = HORSE_INPUT) -> None:
        self.service = service
        self.spec = spec
        self.low, self.high = ranges.limits(spec.names, service.config.tick.length_scale)
        """Plausible range of each channel in service units."""

    async def authenticate(self, websocket: WebSocket, offered: list[str]) -> dict[str, Any] | None:
        """Check the token (subprotocol or first message); return the first message if read."""
        config = self.service.config
        if not config.token_required:
            return None
        if auth.token_matches(config.security.token, auth.token_from_subprotocols(offered)):
            return None
        try:
            first = await asyncio.wait_for(websocket.receive(), 5.0)
            text = first.get("text") or first.get("bytes")
            obj = parse_message(text or b"", config.input.max_message_bytes) if text else {}
        except (TimeoutError, BadFrame):
            obj = {}
        if not auth.token_matches(config.security.token, obj.get("token")):
            raise auth.Unauthorized
        return obj

    async def __call__(self, websocket: WebSocket) -> None:
        service = self.service
        config = service.config
        offered = list(websocket.scope.get("subprotocols", []))
        await websocket.accept(subprotocol=auth.accepted_subprotocol(offered))
        try:
            first = await self.authenticate(websocket, offered)
        except auth.Unauthorized:
            service.metrics.bad_frames["unauthorized"] += 1
            await send_quietly(websocket, {"type": "error", "reason": "unauthorized", "message": "token required"}, 1.0)
            with contextlib.suppress(Exception):  # it may have left already
                await websocket.close(code=4401, reason="unauthorized")
            return
        spec = self.spec
        producer_id = next_producer_id()
        producer = Producer(id=producer_id, name=f"{spec.prefix}-{producer_id}", spec=spec, websocket=websocket)
        service.arbiter.producers[producer.id] = producer
        await websocket.send_json(self.welcome(producer))
        driving: bool | None = None
        try:
            if first is not None:
                self.handle(producer, first)
            while True:
                message = await websocket.receive()
                if message["type"] == "websocket.disconnect":
                    service.metrics.count_disconnect(message)
                    break
                data = message.get("text")
                if data is None:
                    data = message.get("bytes") or b""
                now = time.perf_counter()
                try:
                    result = self.handle(producer, parse_message(data, config.input.max_message_bytes), now)
                except Exception as exc:
                    if not isinstance(exc, BadFrame):  # a bug: answered, counted and logged, never a silent drop
                        log.exception("ingest failed on a message from %s", producer.name)
                        exc = BadFrame("internal_error", "the service failed on this message (see its log)")
                    if await self.reject(producer, exc, now):
                        break
                    continue
                while producer.outbox:
                    await send_quietly(websocket, producer.outbox.pop(0), 1.0)
                if result is not None and result != driving:
                    driving = result
                    await send_quietly(websocket, {"type": "control", "driving": driving}, 1.0)
        except WebSocketDisconnect:
            pass
        finally:
            if service.arbiter.remove(producer.id):
                service.link.tell(cmd.ProducerGone(producer.stream))

    def welcome(self, producer: Producer) -> dict[str, Any]:
        """The first message to a new producer (here and on NATS, ``bus/inbound.py``)."""
        config = self.service.config
        return {
            "type": "welcome",
            "protocol": PROTOCOL_VERSION,
            "session": self.service.session,
            "producer": producer.id,
            "kind": self.spec.what,
            "channels": [{"name": c.name, "unit": c.unit} for c in self.spec.channels],
            "length_scale": config.tick.length_scale,
            "max_message_bytes": config.input.max_message_bytes,
            "max_rate": config.input.max_rate,
        }

    def handle(self, producer: Producer, obj: dict[str, Any], now: float | None = None) -> bool | None:
        """Apply one decoded message; for a frame return whether it drives."""
        kind = obj.get("type", "frame")
        if kind == "hello":
            self.hello(producer, obj)
            return None
        if kind != "frame":
            raise BadFrame("unknown_type", f"unknown message type {kind!r}")
        now = time.perf_counter() if now is None else now
        limits = self.service.config.input
        if now - producer.window_start >= 1.0:
            producer.window_start, producer.window_frames = now, 0
        producer.window_frames += 1
        if producer.window_frames > limits.max_rate:
            raise BadFrame("rate", f"more than {limits.max_rate:g} frames per second")
        spec = self.spec
        frame = decode_frame(obj, producer.order, spec.index, spec.names, spec.what)
        values = producer.merge(producer.convert(frame.values, self.low, self.high))
        step = clock_step(producer.clock, frame.t, now, limits.clock_jump, min(PAUSE_S, limits.hold / 2.0))
        producer.clock = step.clock
        if step.event is not None:
            self.new_segment(producer, frame.t, step)
        producer.accepted += 1
        self.service.metrics.count_frame_in(producer.name)
        arbiter = self.service.arbiter
        drives = arbiter.drives(producer, now)
        producer.last_frame_at = now
        if drives:
            self.service.link.push_input(producer.stream, step.t, now - self.service.link.start, values, spec.kind)
        return drives

    def new_segment(self, producer: Producer, t: float, step: ClockStep) -> None:
        """Tell the producer; after a jump the tick gets a new stream id (a fresh clock
        mapping, a blend); a step back, a pause or a resume keeps it (the time given is continuous)."""
        assert step.event is not None
        producer.segment += 1
        if step.new_stream:
            producer.stream = next_producer_id()
        self.service.metrics.clock_jumps[step.event.direction] += 1
        producer.outbox.append(
            {
                "type": "segment",
                "segment": producer.segment,
                "reason": step.event.value,
                "t": t,
                "previous_t": step.previous_t,
                "jump": step.jump,
            }
        )

    def hello(self, producer: Producer, obj: dict[str, Any]) -> None:
        """Per-connection settings: name, priority, length_scale, channels (order of ``v``)."""
        if "name" in obj:
            if not isinstance(obj["name"], str) or not 0 < len(obj["name"]) <= 64:
                raise BadFrame("wrong_type", "'name' must be a string of 1-64 characters")
            producer.name = obj["name"]
        if "priority" in obj:
            value = obj["priority"]
            if isinstance(value, bool) or not isinstance(value, int) or not -1000 <= value <= 1000:
                raise BadFrame("wrong_type", "'priority' must be an integer -1000..1000")
            producer.priority = value
        if "length_scale" in obj:
            scale = obj["length_scale"]
            if isinstance(scale, bool) or not isinstance(scale, int | float):
                raise BadFrame("wrong_type", "'length_scale' must be a number (25 for metres)")
            low, high = LENGTH_SCALE_RANGE
            if not low <= scale <= high:
                raise BadFrame("out_of_range", f"'length_scale' = {scale!r} is outside [{low:g}, {high:g}]")
            producer.length_gain = float(scale) / self.service.config.tick.length_scale
        if "channels" in obj:
            producer.order = channel_order(obj["channels"], self.spec.index, self.spec.what)

    async def reject(self, producer: Producer, exc: BadFrame, now: float) -> bool:
        """Count and answer a bad message; True when the client keeps abusing (close it)."""
        service = self.service
        limits = service.config.input
        service.metrics.bad_frames[exc.reason] += 1
        producer.rejected += 1
        producer.errors.append(now)
        while producer.errors and now - producer.errors[0] > limits.error_window:
            producer.errors.popleft()
        websocket = producer.websocket
        assert websocket is not None
        await send_quietly(websocket, {"type": "error", "reason": exc.reason, "message": str(exc)}, 1.0)
        if len(producer.errors) > limits.max_errors:
            service.metrics.bad_frames["abuse"] += 1
            await send_quietly(
                websocket, {"type": "error", "reason": "abuse", "message": "too many bad messages; closing"}, 1.0
            )
            await websocket.close(code=1008, reason="too many bad messages")
            return True
        return False
