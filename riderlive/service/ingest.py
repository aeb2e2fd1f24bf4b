"""``/ws/horse`` and ``/ws/saddle``: producers stream horse frames or saddle samples in;
one arbiter picks the one that drives.

The two endpoints share everything (envelope, validation, auth, limits, error replies,
counters) but their channels (:class:`InputSpec`): ``channels.HORSE`` or the six
``channels.SADDLE``. On ``/ws/horse`` a channel a frame omits keeps its last value; on
``/ws/saddle`` it is *missing* for that sample (NaN to the estimator, which holds it).

Arbitration: ``service/arbiter.py`` (docs/protocol.md, "Several producers").

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
import logging
import time
from typing import Any, Protocol

from starlette.websockets import WebSocket, WebSocketDisconnect

from riderlive.ranges import Ranges
from riderlive.realtime import commands as cmd
from riderlive.service import auth
from riderlive.service.arbiter import HORSE_INPUT, Arbiter, InputSpec, Producer, next_producer_id
from riderlive.service.clocks import ClockStep, clock_step
from riderlive.service.codecs import PROTOCOL_VERSION, BadFrame, channel_order, decode_frame, parse_message
from riderlive.service.ports import ServicePort
from riderlive.timecode import TimecodeError

log = logging.getLogger(__name__)
PAUSE_S = 0.1
"""The longest a clock may stand still (or half ``input.hold``, if less) while frames keep
coming before it is paused (sooner at a high rate: ``clocks.ProducerClock.pause_after``):
the service's clock stands in before the tick's hold runs out."""
LENGTH_SCALE_RANGE = (1e-6, 1e6)
"""Accepted ``length_scale`` of a producer's hello (thesis rig units per its length unit)."""


class IngestPort(ServicePort, Protocol):
    """What an input endpoint reads of the service (``service.ports``), and the one arbiter."""

    @property
    def arbiter(self) -> Arbiter: ...


async def send_quietly(websocket: WebSocket, message: dict[str, Any], timeout: float) -> None:
    """Send a JSON message; a client that does not read or has left is ignored."""
    with contextlib.suppress(Exception):  # gone or stuck: its receive loop will end it
        await asyncio.wait_for(websocket.send_json(message), timeout)


class IngestEndpoint:
    """The ``/ws/horse`` (or, with ``SADDLE_INPUT``, ``/ws/saddle``) handler, bound to the running service."""

    def __init__(self, service: IngestPort, ranges: Ranges, spec: InputSpec = HORSE_INPUT) -> None:
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
                service.link.input_pending(now)  # the tick waits a moment for it (realtime/pacing.py)
                try:
                    result = self.handle(producer, parse_message(data, config.input.max_message_bytes), now)
                except Exception as exc:
                    service.link.input_pending(None)
                    if not isinstance(exc, BadFrame):  # a bug: answered, counted and logged, never a silent drop
                        log.exception("ingest failed on a message from %s", producer.name)
                        exc = BadFrame("internal_error", "the service failed on this message (see its log)")
                    if await self.reject(producer, exc, now):
                        break
                    continue
                service.link.input_pending(None)
                while producer.outbox:
                    await send_quietly(websocket, producer.outbox.pop(0), 1.0)
                if result is not None and result != driving:
                    driving = result
                    await send_quietly(websocket, {"type": "control", "driving": driving}, 1.0)
        except WebSocketDisconnect:
            pass
        finally:
            service.timecode.forget(producer.stream)
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
        if "tc" in obj:
            self.timecode(producer, frame.t, obj, now)
        producer.accepted += 1
        self.service.metrics.count_frame_in(producer.name)
        arbiter = self.service.arbiter
        drives = arbiter.drives(producer, now)
        producer.last_frame_at = now
        if drives:
            received = now - self.service.link.start
            self.service.link.push_input(producer.stream, step.t, received, values, spec.kind, rebased=step.rebased)
        return drives

    def timecode(self, producer: Producer, t: float, obj: dict[str, Any], now: float) -> None:
        """A frame's ``tc`` (and ``tc_rate``; docs/protocol.md, "Timecode"). An unusable one
        (malformed, another rate) is counted and answered at most once a second, and ignored:
        the frame still drives (its motion is valid). A jump is counted and told."""
        try:
            jump = self.service.timecode.producer_label(producer.stream, t, obj["tc"], obj.get("tc_rate"))
        except TimecodeError as exc:
            if now - producer.timecode_error_at >= 1.0:
                producer.timecode_error_at = now
                producer.outbox.append({"type": "error", "reason": exc.reason, "message": str(exc)})
            return
        if jump is not None:
            producer.outbox.append({"type": "timecode", "reason": "jump", "frames": jump, "tc": obj["tc"]})

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
