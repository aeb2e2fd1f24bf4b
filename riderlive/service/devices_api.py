"""REST for the devices near people: arm, disarm, e-stop, reset, reload; health; metrics.

    POST /api/arm     {"device": "bench3"}        the name is the confirmation
    POST /api/disarm  {"device": "bench3"} | {}   ease to park, outputs off (all when omitted)
    POST /api/estop                               latched e-stop of every device
    POST /api/reset   {"device": ...} | {}        clear the e-stop / faults: disarmed, never armed
    POST /api/reload  {"device": "bench3"}        re-read its file (refused while it moves)

Arm, reset and reload need the token whenever one is configured, even on loopback;
disarm follows the other control calls (a token when bound beyond loopback);
``auth.WriteGuard`` checks it (``auth.WRITE_RULES``) before a body is read. An
e-stop is never locked: latched by the outermost ASGI layer before anything else
(:mod:`riderlive.service.estop_first`), token or not; one without the token is
counted apart and logged.
    GET  /api/devices                             lifecycle of each device, supervision
    GET  /healthz, /readyz                        liveness and readiness (no token)

A refused request changes nothing and answers 401/404/409/422/503 with
``{"detail": {"refusal": REASON, "message": ...}}``; every refusal is counted in
``/metrics`` by action and reason.
"""

from __future__ import annotations

import logging
import sys
import time
from collections import Counter
from typing import Any, Protocol

import pydantic
from fastapi import FastAPI, HTTPException, Request
from fastapi.responses import JSONResponse

from riderlive.devices.latch import StopSource
from riderlive.devices.lifecycle import REFUSAL_STATUS, DeviceState, Refusal
from riderlive.devices.registry import DeviceSpec, plan
from riderlive.names import NAME_PATTERN
from riderlive.prometheus import Exposition, Kind, sample
from riderlive.realtime import commands as cmd
from riderlive.service import auth
from riderlive.service.config import ServiceConfig
from riderlive.service.estop_first import EStopFirst, stamps
from riderlive.service.ports import ControlPort
from riderlive.tickframe import computed_parts

log = logging.getLogger(__name__)
NAME = pydantic.Field(pattern=NAME_PATTERN)
"""A device name: a name like every user-given name (riderlive/names.py)."""
BY = pydantic.Field(default=None, pattern=r"^[A-Za-z0-9][A-Za-z0-9 _-]{0,31}$")


class DeviceRequest(pydantic.BaseModel):
    model_config = pydantic.ConfigDict(extra="forbid")
    device: str = NAME
    by: str | None = BY
    """Who is asking, for the log (``page``, a script's name); the client address is added."""


class AnyDeviceRequest(pydantic.BaseModel):
    model_config = pydantic.ConfigDict(extra="forbid")
    device: str | None = pydantic.Field(default=None, pattern=NAME_PATTERN)
    by: str | None = BY


def plan_devices(config: ServiceConfig) -> tuple[DeviceSpec, ...]:
    """The configured devices, validated (the frame parts each consumes, too: ``MissingPart``)
    and fitted to the tick rate; prints the wire budget."""
    specs = []
    computed = computed_parts(saddle_input=config.input.saddle)
    if config.rig.file:
        spec, text = plan(
            "dynamixel", config.rig.file, config.rig.port, config.tick.rate, config.rig.rate_policy, computed=computed
        )
        print(f"riderlive serve: rig {text}", file=sys.stderr, flush=True)
        specs.append(spec)
    platform = config.platform
    if platform.file:
        options: dict[str, Any] = {"device": platform.device, "heartbeat_ms": platform.heartbeat_ms}
        spec, text = plan(
            "platform",
            platform.file,
            platform.port,
            config.tick.rate,
            platform.rate_policy,
            options=options,
            computed=computed,
        )
        print(f"riderlive serve: platform {text}", file=sys.stderr, flush=True)
        specs.append(spec)
    return tuple(specs)


class DeviceMetrics:
    """What the web process counts about devices."""

    def __init__(self) -> None:
        self.refusals: Counter[tuple[str, str]] = Counter()
        self.estops: Counter[tuple[str, bool]] = Counter()
        """E-stop requests by (source label, authorized: with the token or where none is needed)."""


class DevicesPort(ControlPort, Protocol):
    """What the device routes and their metrics use of the service (``runtime.Service``)."""

    device_metrics: DeviceMetrics
    """Set by :func:`add_device_routes`."""


def add_device_routes(app: FastAPI, service: DevicesPort) -> None:
    config = service.config
    counts = DeviceMetrics()
    service.device_metrics = counts

    def latch_now(source: StopSource) -> float:  # the supervisor of the running service (bound late)
        return service.supervisor.estop(source)

    app.add_middleware(EStopFirst, estop=latch_now)  # outermost: added last, after RestGuard and CORS

    def refuse(action: str, reason: Refusal | str, message: str) -> HTTPException:
        reason = Refusal(reason)
        counts.refusals[(action, reason.value)] += 1
        return HTTPException(REFUSAL_STATUS.get(reason, 409), {"refusal": reason.value, "message": message})

    def operator(request: Request) -> str:
        """Who asks (the token of every write was checked by auth.WriteGuard before its body)."""
        return f"rest {request.client.host if request.client else '?'}"

    async def answer(action: str, build: Any) -> dict[str, Any]:
        reply: cmd.Reply = await service.supervisor.ask(build)
        if not reply.ok:
            raise refuse(action, reply.refusal or Refusal.NOT_READY, reply.message)
        return {"ok": True, "states": reply.states, "message": reply.message}

    def who(base: str, body: DeviceRequest | AnyDeviceRequest | None) -> str:
        return base if body is None or not body.by else f"{base} ({body.by})"

    @app.post("/api/arm", summary="Arm a device by name (token whenever one is configured): it soft-starts")
    async def arm(request: Request, body: DeviceRequest) -> dict[str, Any]:
        by = who(operator(request), body)
        for check in service.arm_checks:  # e.g. no stage heartbeat (riderlive.bus.rig)
            if (why := check()) is not None:
                raise refuse("arm", Refusal.NOT_READY, why)
        return await answer("arm", lambda r: cmd.Arm(body.device, by, r))

    @app.post("/api/disarm", summary="Ease a device (all when none named) to park, then outputs off")
    async def disarm(request: Request, body: AnyDeviceRequest | None = None) -> dict[str, Any]:
        by = who(operator(request), body)
        return await answer("disarm", lambda r: cmd.Disarm(body.device if body else None, by, r))

    @app.post("/api/estop", summary="Emergency stop, latched: every device's outputs off at once (never locked)")
    async def estop(request: Request) -> dict[str, Any]:
        first = stamps(request.scope)
        if first is None:  # not through the outer layer (never in the service): latch here
            first = (service.supervisor.estop(StopSource.REST), time.perf_counter())
        received, latched = first
        given = auth.bearer(request.headers.get("authorization"))
        authorized = auth.token_matches(config.security.token, given) or not config.token_required
        counts.estops[(StopSource.REST.label, authorized)] += 1
        if not authorized:
            host = request.client.host if request.client else "?"
            log.warning("e-stop without the token from %s: latched (an e-stop is never locked)", host)
        return {"estop": True, "received_at": received, "latched_at": latched, "authorized": authorized}

    @app.post("/api/reset", summary="Clear the e-stop and device faults: disarmed (never arms)")
    async def reset(request: Request, body: AnyDeviceRequest | None = None) -> dict[str, Any]:
        by = who(operator(request), body)
        result = await answer("reset", lambda r: cmd.Reset(body.device if body else None, by, r))
        return {**result, "estop": False}

    @app.post("/api/reload", summary="Re-read a device's file and connect it again (refused while it moves)")
    async def reload(request: Request, body: DeviceRequest) -> dict[str, Any]:
        by = who(operator(request), body)
        return await answer("reload", lambda r: cmd.Reload(body.device, by, r))

    @app.get("/api/devices", summary="Each device's lifecycle state; tick supervision and guardian")
    async def devices(request: Request) -> dict[str, Any]:
        if (
            config.security.publish_requires_token
            and config.token_required
            and not auth.token_matches(config.security.token, auth.bearer(request.headers.get("authorization")))
        ):
            service.metrics.bad_frames[auth.UNAUTHORIZED] += 1
            raise refuse("observe", Refusal.UNAUTHORIZED, auth.TOKEN_REQUIRED)
        status = service.link.status()
        return {
            "devices": status.get("devices", []),
            "platform": status.get("platform"),
            "estop": service.link.latch.latched,
            "guardian": status.get("guardian"),
            "supervision": service.supervisor.snapshot(),
        }

    @app.get("/healthz", summary="Liveness: 200 unless the tick has been down for a minute")
    async def healthz() -> JSONResponse:
        live = service.supervisor.live()
        return JSONResponse({"status": "ok" if live else "down", **service.supervisor.snapshot()}, 200 if live else 503)

    @app.get("/readyz", summary="Readiness: 200 while the tick is up and beating")
    async def readyz() -> JSONResponse:
        ready = service.supervisor.ready()
        body = {"status": "ready" if ready else "not ready", "tick_up": service.supervisor.up}
        return JSONResponse(body, 200 if ready else 503)


SUPERVISION_COUNTERS: tuple[tuple[str, str], ...] = (
    ("restarts", "Tick processes started again after a death or a hang."),
    ("deaths", "Tick processes that exited unasked."),
    ("hangs", "Tick processes killed for missing their heartbeat."),
    ("stalls", "Heartbeat gaps past the hang threshold that the host explained: counted, not punished."),
    ("takeovers", "Tick generations started from a warm spare."),
)
"""Supervision's counters (``Supervisor.snapshot``), as ``riderlive_tick_*_total``."""


def render_device_metrics(service: DevicesPort) -> str:
    """Prometheus text: supervision, guardian, each device's state and counters, refusals."""
    sup = service.supervisor.snapshot()
    out = Exposition()
    out.one(
        "riderlive_tick_up",
        Kind.GAUGE,
        "1 once the serving tick generation has beaten (0 from a failure until the next one beats).",
        bool(sup["up"]),
    )
    for key, help_text in SUPERVISION_COUNTERS:
        out.one(f"riderlive_tick_{key}_total", Kind.COUNTER, help_text, sup[key])
    guardian = sup["guardian"]
    out.one("riderlive_guardian_up", Kind.GAUGE, "1 while the guardian runs.", bool(guardian["alive"]))
    for key in ("restarts", "takeovers"):
        out.one(f"riderlive_guardian_{key}_total", Kind.COUNTER, f"Guardian {key}.", guardian[key])
    latch = service.link.latch
    out.one("riderlive_estop_latched", Kind.GAUGE, "1 while the e-stop is latched.", bool(latch.latched))
    out.one("riderlive_estop_requests_total", Kind.COUNTER, "E-stop requests (all sources).", latch.requested)
    name = "riderlive_estop_requests_by_source_total"
    by_source = [
        sample(name, n, {"source": source, "authorized": "yes" if ok else "no"})
        for (source, ok), n in sorted(service.device_metrics.estops.items())
    ]
    help_text = "E-stop requests the web process received, by source and whether it was authorized (never refused)."
    out.family(name, Kind.COUNTER, help_text, by_source)
    states, events = [], []
    for device in service.link.status().get("devices", []):
        device_name = str(device.get("name"))
        for state in DeviceState:
            now_in = device.get("state") == state.value
            states.append(sample("riderlive_device_state", now_in, {"device": device_name, "state": state.value}))
        for event, value in sorted((device.get("counters") or {}).items()):
            events.append(sample("riderlive_device_events_total", value, {"device": device_name, "event": event}))
    out.family("riderlive_device_state", Kind.GAUGE, "1 for the state each device is in.", states)
    out.family("riderlive_device_events_total", Kind.COUNTER, "Device lifecycle and bus events by kind.", events)
    refusals = [
        sample("riderlive_device_refusals_total", n, {"action": a, "reason": r})
        for (a, r), n in sorted(service.device_metrics.refusals.items())
    ]
    help_text = "Operator requests refused, by action and reason."
    out.family("riderlive_device_refusals_total", Kind.COUNTER, help_text, refusals)
    return out.text()
