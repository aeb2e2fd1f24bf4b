"""What a rig accepts from the stage: horse and saddle input, and control requests.

**Input** (``riderlive.v1.<stage>.<rig>.horse.<producer>`` and
``...<rig>.saddle.<producer>``): each (kind, producer name) is one producer of the
service's one arbiter, exactly as a ``/ws/horse`` or ``/ws/saddle`` connection is
(priority, timeout, ranges, rate, clock jumps: ``service/ingest.py``, whose
``IngestEndpoint.handle`` validates every message), messages in the same JSON or msgpack
forms (``hello``, ``frame``, and ``bye``). When the service needs a token for ingest, a
producer sends it in its hello (``"token"``) before its frames count. Answers
(``welcome``, ``control``, ``segment``, ``error``) go to the message's reply subject
when it has one. A producer silent for ``nats.producer_forget`` s is forgotten; at most
``publish.max_clients`` producers (horse and saddle together) at once (more:
``too_many_producers``).

**Control** (``riderlive.v1.<stage>.<rig>.control``, request/reply): ``{"action": A,
"device": ..., "by": ..., "token": ...}`` with A one of ``state``, ``arm``, ``disarm``,
``reset``, ``reload``, ``estop``. The token rules are REST's (``service/devices_api.py``):
arm, reset and reload need ``security.token`` whenever one is configured; disarm
when the service requires a token; ``state`` when publishing does; an ``estop`` is
never locked: latched first, token or not (counted apart when not authorized). With
``nats.control_auth = "credentials"`` the broker's permissions decide instead. The
answer is ``{"ok": true, ...}`` or ``{"ok": false, "refusal": R, "message": ...}``,
refusals counted with REST's (``riderlive_device_refusals_total``).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any, Protocol

import orjson
import pydantic

from riderlive.bus.subjects import Kind, parse
from riderlive.bus.transport import Message, Transport
from riderlive.devices.latch import StopSource
from riderlive.devices.lifecycle import Refusal
from riderlive.realtime import commands as cmd
from riderlive.service import auth
from riderlive.service.arbiter import Arbiter, Producer, next_producer_id
from riderlive.service.codecs import BadFrame, parse_message
from riderlive.service.devices_api import AnyDeviceRequest, DeviceRequest
from riderlive.service.ingest import IngestEndpoint
from riderlive.service.ports import ControlPort, StopCounts

log = logging.getLogger(__name__)
ARMING = frozenset({"arm", "reset", "reload"})
ACTIONS = ("state", "arm", "disarm", "reset", "reload", "estop")


def dumps(message: dict[str, Any]) -> bytes:
    return orjson.dumps(message)


def parse_payload(data: bytes, max_bytes: int) -> dict[str, Any]:
    """A NATS payload (always bytes) as ``/ws/horse`` reads a message: JSON text when it
    starts with ``{`` (after blanks), else msgpack; :class:`BadFrame` otherwise."""
    if data.lstrip()[:1] == b"{":
        if len(data) > max_bytes:
            raise BadFrame("oversize", f"message of {len(data)}+ bytes exceeds {max_bytes} bytes")
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise BadFrame("malformed", f"cannot decode message: {exc}") from None
        return parse_message(text, max_bytes)
    return parse_message(data, max_bytes)


class InboundPort(ControlPort, Protocol):
    """What NATS producers and control use of the service (``runtime.Service``)."""

    @property
    def arbiter(self) -> Arbiter: ...

    @property
    def ingest(self) -> IngestEndpoint:
        """``/ws/horse``'s validation (a NATS horse producer is validated as one)."""
        ...

    @property
    def saddle_ingest(self) -> IngestEndpoint: ...

    @property
    def device_metrics(self) -> StopCounts:
        """E-stops and refusals counted for ``/metrics``, whichever path they came by."""
        ...


ProducerKey = tuple[str, str]
"""(kind, producer name): ``("horse", "mocap")``, ``("saddle", "imu")``."""


class ProducerInput:
    """NATS producers (horse and saddle) feeding the service's arbiter (see the module docstring)."""

    def __init__(self, service: InboundPort, transport: Transport, trust_broker: bool, forget: float) -> None:
        self.service = service
        self.transport = transport
        self.trust_broker = trust_broker
        self.forget = forget
        self.endpoints: dict[str, IngestEndpoint] = {Kind.HORSE: service.ingest}
        """The websocket endpoints' own validation, one per input kind accepted (``input.saddle``)."""
        if service.config.input.saddle:
            self.endpoints[Kind.SADDLE] = service.saddle_ingest
        self.producers: dict[ProducerKey, Producer] = {}
        self.authorized: set[ProducerKey] = set()
        self.driving: dict[ProducerKey, bool] = {}

    @property
    def needs_token(self) -> bool:
        return self.service.config.token_required and not self.trust_broker

    async def on_message(self, msg: Message) -> None:
        service = self.service
        parsed = parse(msg.subject)
        endpoint = None if parsed is None else self.endpoints.get(parsed.kind)
        if parsed is None or endpoint is None or not parsed.known_version:
            service.metrics.bad_frames["unknown_version"] += 1
            await self._answer(msg, {"type": "error", "reason": "unknown_version", "message": msg.subject[:200]})
            return
        key = (parsed.kind, parsed.producer)
        producer = self.producers.get(key)
        if producer is None and len(self.producers) >= service.config.publish.max_clients:
            service.metrics.bad_frames["too_many_producers"] += 1
            message = f"more than {service.config.publish.max_clients} NATS producers (publish.max_clients)"
            await self._answer(msg, {"type": "error", "reason": "too_many_producers", "message": message})
            return
        if producer is None:
            kind = "" if parsed.kind == Kind.HORSE else f"{parsed.kind}:"
            producer = Producer(id=next_producer_id(), name=f"nats:{kind}{parsed.producer}", spec=endpoint.spec)
            self.producers[key] = producer
            service.arbiter.producers[producer.id] = producer
            await self._answer(msg, endpoint.welcome(producer))
        now = time.perf_counter()
        try:
            obj = parse_payload(msg.data, service.config.input.max_message_bytes)
            if self.needs_token and key not in self.authorized:
                if not auth.token_matches(service.config.security.token, obj.get("token")):
                    raise BadFrame(
                        "unauthorized", "token required: send it in a hello ({'type': 'hello', 'token': ...})"
                    )
                self.authorized.add(key)
            if obj.get("type") == "bye":
                self.drop(key)
                return
            obj.pop("token", None)
            drives = endpoint.handle(producer, obj, now)
        except Exception as exc:
            if not isinstance(exc, BadFrame):  # a bug: answered, counted and logged
                log.exception("ingest failed on a NATS message from %s", producer.name)
                exc = BadFrame("internal_error", "the service failed on this message (see its log)")
            service.metrics.bad_frames[exc.reason] += 1
            producer.rejected += 1
            producer.last_frame_at = max(producer.last_frame_at, now - self.forget / 2.0)
            await self._answer(msg, {"type": "error", "reason": exc.reason, "message": str(exc)})
            return
        while producer.outbox:
            await self._answer(msg, producer.outbox.pop(0))
        if drives is not None and self.driving.get(key) != drives:
            self.driving[key] = drives
            await self._answer(msg, {"type": "control", "driving": drives})

    def accepted(self, kind: Kind) -> int:
        """Frames accepted so far from the current NATS producers of ``kind``."""
        return sum(p.accepted for (k, _), p in self.producers.items() if k == kind)

    async def _answer(self, msg: Message, message: dict[str, Any]) -> None:
        if msg.reply:
            await self.transport.publish(msg.reply, dumps(message))

    def drop(self, key: ProducerKey) -> None:
        """Forget a producer: its stream ends (the tick eases or another producer drives)."""
        producer = self.producers.pop(key, None)
        self.authorized.discard(key)
        self.driving.pop(key, None)
        if producer is not None and self.service.arbiter.remove(producer.id):
            self.service.link.send(cmd.ProducerGone(producer.stream))

    def sweep(self, now: float) -> None:
        """Forget producers silent for ``forget`` seconds."""
        for key, producer in list(self.producers.items()):
            if now - producer.last_frame_at > self.forget and producer.accepted + producer.rejected > 0:
                self.drop(key)

    def close(self) -> None:
        for key in list(self.producers):
            self.drop(key)


class Control:
    """The control request/reply subject (see the module docstring)."""

    def __init__(
        self,
        service: InboundPort,
        transport: Transport,
        trust_broker: bool,
        arm_refusal: Callable[[], str | None],
        describe: Callable[[], dict[str, Any]],
    ) -> None:
        self.service = service
        self.transport = transport
        self.trust_broker = trust_broker
        self.arm_refusal = arm_refusal
        self.describe = describe

    def _needs_token(self, action: str) -> bool:
        config = self.service.config
        if self.trust_broker:
            return False
        if action in ARMING:
            return config.arming_token is not None
        if action == "state":
            return config.security.publish_requires_token
        return config.token_required

    async def on_message(self, msg: Message) -> None:
        answer = await self.handle(msg)
        if msg.reply:
            await self.transport.publish(msg.reply, dumps(answer))

    def refuse(self, action: str, reason: Refusal | str, message: str) -> dict[str, Any]:
        reason = str(reason)
        self.service.device_metrics.refusals[(action, reason)] += 1
        return {"ok": False, "action": action, "refusal": reason, "message": message}

    async def handle(self, msg: Message) -> dict[str, Any]:
        service = self.service
        parsed = parse(msg.subject)
        if parsed is None or not parsed.known_version:
            service.metrics.bad_frames["unknown_version"] += 1
            return {"ok": False, "refusal": "unknown_version", "message": f"this rig speaks {msg.subject[:200]!r} v1"}
        try:
            obj = parse_payload(msg.data, service.config.input.max_message_bytes)
        except BadFrame as exc:
            service.metrics.bad_frames[exc.reason] += 1
            return {"ok": False, "refusal": exc.reason, "message": str(exc)}
        action = obj.pop("action", None)
        if action not in ACTIONS:
            service.metrics.bad_frames["unknown_type"] += 1
            return {"ok": False, "refusal": "unknown_action", "message": f"action must be one of {', '.join(ACTIONS)}"}
        token = obj.pop("token", None)
        obj.pop("id", None)
        if action == "estop":  # never locked (service/estop_first.py): latched first, token or not
            latched = service.supervisor.estop(StopSource.NATS)
            authorized = not self._needs_token(action) or auth.token_matches(service.config.security.token, token)
            service.device_metrics.estops[(StopSource.NATS.label, authorized)] += 1
            return {"ok": True, "action": "estop", "latched_at": latched, "authorized": authorized}
        if self._needs_token(action) and not auth.token_matches(service.config.security.token, token):
            service.metrics.bad_frames["unauthorized"] += 1
            return self.refuse(action, Refusal.UNAUTHORIZED, 'token required: add "token" to the request')
        if action == "state":
            return {"ok": True, **self.describe()}
        try:
            body: DeviceRequest | AnyDeviceRequest
            body = (DeviceRequest if action in ("arm", "reload") else AnyDeviceRequest).model_validate(obj)
        except pydantic.ValidationError as exc:
            service.metrics.bad_frames["wrong_type"] += 1
            return {"ok": False, "refusal": "invalid", "message": str(exc.errors()[0]["msg"])}
        by = f"nats {parsed.stage}" + (f" ({body.by})" if body.by else "")
        if action == "arm":
            why = self.arm_refusal()
            if why is not None:
                return self.refuse(action, Refusal.NOT_READY, why)
        device = body.device
        build: Callable[[int], cmd.Request]
        if action == "arm":
            build = lambda r: cmd.Arm(str(device), by, r)  # noqa: E731
        elif action == "disarm":
            build = lambda r: cmd.Disarm(device, by, r)  # noqa: E731
        elif action == "reset":
            build = lambda r: cmd.Reset(device, by, r)  # noqa: E731
        else:
            build = lambda r: cmd.Reload(str(device), by, r)  # noqa: E731
        reply = await service.supervisor.ask(build)
        if not reply.ok:
            return self.refuse(action, reply.refusal or Refusal.NOT_READY, reply.message)
        return {"ok": True, "action": action, "states": reply.states, "message": reply.message}
