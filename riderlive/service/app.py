"""The FastAPI application: websockets, REST control, metrics and the page.

REST paths are stable (the browser page calls them); every body is described in the
OpenAPI schema at ``/openapi.json`` (browsable at ``/docs``). Mutating calls need
``Authorization: Bearer <token>`` when a token is required, checked for every write by
``auth.WriteGuard`` before the body is read (see ``auth``). Bad bodies
get a 4xx with a JSON ``detail``, never a 500 (``service/rest.py``).
"""

from __future__ import annotations

import logging
import math
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any, Literal

from fastapi import Depends, FastAPI, HTTPException, Request
from fastapi.exceptions import RequestValidationError
from fastapi.middleware.cors import CORSMiddleware
from fastapi.responses import HTMLResponse, PlainTextResponse
from fastapi.staticfiles import StaticFiles

import riderlive.horse as horse_module
from riderlive import __version__
from riderlive.configfile import ConfigError
from riderlive.horse.terrain import MAX_SLOPE, TRANSITION
from riderlive.realtime import commands as cmd
from riderlive.rules.animator import AnimatorLayer
from riderlive.rules.params import find_preset, load_preset, shipped_presets
from riderlive.service import auth
from riderlive.service.arbiter import SADDLE_INPUT
from riderlive.service.config import ServiceConfig
from riderlive.service.devices_api import add_device_routes, render_device_metrics
from riderlive.service.fit_api import REFERENCE_LIMIT, REFERENCE_PATH, add_fit_routes, with_references
from riderlive.service.latency_api import add_latency_routes
from riderlive.service.metrics import render
from riderlive.service.platform_api import add_platform_routes, render_platform_metrics
from riderlive.service.rest import (
    AnimatorBody,
    PerformRequest,
    PresetRequest,
    RecordStart,
    RestGuard,
    SourceRequest,
    invalid_request,
)
from riderlive.service.runtime import Service
from riderlive.service.takes_api import add_take_routes
from riderlive.takes.recorder import TakeExists, list_takes

log = logging.getLogger(__name__)

STATIC_DIR = Path(__file__).resolve().parent.parent / "web" / "static"


def create_app(config: ServiceConfig | None = None) -> FastAPI:
    """The app; the lifespan starts the tick process and stops it (parking the rig)."""
    config = config or ServiceConfig()
    service = Service(config)

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        await service.start()
        try:
            yield
        finally:
            await service.stop()

    app = FastAPI(title="riderlive", version=__version__, lifespan=lifespan)
    app.state.service = service
    app.add_exception_handler(RequestValidationError, invalid_request)

    def unauthorized(action: str | None) -> None:
        service.metrics.bad_frames[auth.UNAUTHORIZED] += 1
        if action is not None:
            service.device_metrics.refusals[(action, auth.UNAUTHORIZED)] += 1

    # Innermost first: the token of every write before its body is read (auth.WriteGuard),
    # inside the size limit (a Content-Length over it is 413 unread) and CORS (its headers
    # reach a browser's 401 too).
    app.add_middleware(
        auth.WriteGuard, token=config.security.token, required=config.token_required, refused=unauthorized
    )
    app.add_middleware(
        RestGuard,
        limit=config.input.max_message_bytes,
        rejected=service.metrics.rest_rejected,
        larger=((REFERENCE_PATH, REFERENCE_LIMIT),),  # a take's reference rider is a file
    )
    if config.server.cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=config.server.cors_origins,
            allow_methods=["GET", "PUT", "PATCH", "POST"],
            allow_headers=["Authorization", "Content-Type"],
        )

    def observe(request: Request) -> None:
        """Reads need the token only with ``security.publish_requires_token`` (writes: auth.WriteGuard)."""
        if (
            config.security.publish_requires_token
            and config.token_required
            and not auth.token_matches(config.security.token, auth.bearer(request.headers.get("authorization")))
        ):
            service.metrics.bad_frames[auth.UNAUTHORIZED] += 1
            raise HTTPException(401, auth.TOKEN_REQUIRED)

    preset_dirs = [Path(d) for d in config.tick.preset_dirs]
    obs = [Depends(observe)]
    app.add_api_websocket_route("/ws/horse", service.ingest)
    if config.input.saddle:
        app.add_api_websocket_route("/ws/saddle", service.saddle_ingest)
    app.add_api_websocket_route("/ws/rider", service.hub)

    @app.get("/api/state", dependencies=obs, summary="Everything about the running service")
    async def get_state() -> dict[str, Any]:
        return service.state()

    @app.put("/api/source", summary="Choose the source: procedural, replay of a take, or live")
    async def put_source(body: SourceRequest) -> dict[str, Any]:
        try:
            return await service.set_source(body.model_dump())
        except TakeExists as exc:
            raise HTTPException(409, str(exc)) from None
        except FileNotFoundError:
            raise HTTPException(404, "no such take") from None
        except (ValueError, OSError) as exc:
            raise HTTPException(400, str(exc)) from None

    @app.get("/api/horse", dependencies=obs, summary="The procedural horse's gaits (speed ranges, m/s) and moves")
    async def horse() -> dict[str, Any]:
        gaits = {
            g.value: {"speed": list(spec.speed), "default": spec.default_speed}
            for g, spec in horse_module.GAIT_TABLE.items()
        }
        ground = {"max_slope": MAX_SLOPE, "transition": TRANSITION}  # deg; m over which a new ground eases in
        return {"gaits": gaits, "moves": list(horse_module.MOVES), "terrain": ground}

    @app.post("/api/horse/perform", summary="Ask the procedural horse for a move")
    async def perform(body: PerformRequest) -> dict[str, Any]:
        if body.move not in horse_module.MOVES:
            raise HTTPException(422, f"unknown move {body.move!r}; choose one of {', '.join(horse_module.MOVES)}")
        if not service.link.tell(cmd.Perform(body.move)):
            raise HTTPException(503, "the tick is restarting: the move was not queued; ask again")
        return {"move": body.move, "queued": True}

    @app.get("/api/presets", dependencies=obs, summary="The shipped rule presets and the current one")
    async def presets() -> dict[str, Any]:
        return {"presets": shipped_presets(preset_dirs), "current": service.params.name}

    @app.put("/api/preset", summary="Load a preset by name (animator offsets are kept)")
    async def put_preset(body: PresetRequest) -> dict[str, Any]:
        path = find_preset(body.name, preset_dirs)
        if path is None:
            raise HTTPException(404, f"no preset {body.name!r}; GET /api/presets lists them")
        try:
            params = load_preset(path)
            service.set_model(params=params)
        except ConfigError as exc:  # the file's contents stay in the server's log
            log.warning("preset %s cannot be used: %s", path, exc)
            raise HTTPException(422, f"preset {body.name!r} cannot be used (see the service log)") from None
        except ValueError as exc:
            raise HTTPException(422, str(exc)) from None
        return {"current": params.name}

    @app.get("/api/params", dependencies=obs, summary="All rule parameters as dotted keys")
    async def get_params() -> dict[str, float]:
        return service.params.flat()

    @app.patch("/api/params", summary='Change parameters live: {"head.lift_gain": 10.0}')
    async def patch_params(changes: dict[str, float]) -> dict[str, float]:
        if any(not math.isfinite(v) for v in changes.values()):
            raise HTTPException(422, "parameters must be finite numbers")
        try:
            params = service.params.with_values(changes)
            service.set_model(params=params)
        except (KeyError, ValueError) as exc:
            raise HTTPException(422, str(exc)) from None
        return params.flat()

    @app.get("/api/animator", dependencies=obs, summary="Animator offsets and gains per rider channel")
    async def get_animator() -> AnimatorBody:
        return AnimatorBody(offsets=service.animator.offsets, gains=service.animator.gains)

    @app.put("/api/animator", summary="Replace the animator offsets and gains")
    async def put_animator(body: AnimatorBody) -> AnimatorBody:
        try:
            animator = AnimatorLayer(offsets=dict(body.offsets), gains=dict(body.gains))
            service.set_model(animator=animator)
        except (KeyError, ValueError) as exc:
            raise HTTPException(422, str(exc)) from None
        return body

    @app.post("/api/record/start", summary="Start recording a take (409 if it exists)")
    async def record_start(body: RecordStart | None = None) -> dict[str, Any]:
        body = body or RecordStart()
        try:
            name = service.start_recording(body.name, body.overwrite)
        except TakeExists as exc:
            raise HTTPException(409, str(exc)) from None
        except (ValueError, OSError) as exc:
            raise HTTPException(400, str(exc)) from None
        return {"recording": name}

    @app.post("/api/record/stop", summary="Stop recording; the take is complete on disk")
    async def record_stop() -> dict[str, Any]:
        return {"take": service.stop_recording()}

    @app.get("/api/takes", dependencies=obs, summary="Recorded takes with their start timecode, newest first")
    async def takes(order: Literal["modified", "timecode"] = "modified") -> dict[str, Any]:
        """``?order=timecode``: by start timecode (earliest first; takes without one last)."""
        return {"takes": with_references(list_takes(config.takes.directory, order), config.takes.directory)}

    add_take_routes(app, service, obs)  # take download and bake, parameter groups (the page)
    add_fit_routes(app, service, obs)  # a take's reference rider, fit a preset to it

    add_device_routes(app, service)  # arm, disarm, estop, reset, reload, devices, healthz, readyz
    add_platform_routes(app, service, obs)  # GET and PATCH /api/platform
    add_latency_routes(app, service, obs)  # /api/latency

    @app.get("/metrics", dependencies=obs, response_class=PlainTextResponse, summary="Prometheus metrics")
    async def metrics() -> PlainTextResponse:
        producers = service.arbiter.producers.values()
        saddles = sum(p.spec is SADDLE_INPUT for p in producers)
        counters = service.link.counters.snapshot()
        text = render(
            service.metrics,
            counters,
            service.hub.snapshot(),
            len(producers),
            saddles,
            latency=service.latency(),
            handovers=service.arbiter.handover_counts(),
        )
        text += render_device_metrics(service)
        text += render_platform_metrics(service)
        if service.host_workers is not None:
            text += service.host_workers.stats.prometheus()
        if service.stage is not None:
            from riderlive.bus.rig import render_metrics as render_stage_metrics

            text += render_stage_metrics(service.stage)
        return PlainTextResponse(text, media_type="text/plain; version=0.0.4")

    if STATIC_DIR.is_dir():
        app.mount("/", StaticFiles(directory=STATIC_DIR, html=True), name="page")
    else:

        @app.get("/", response_class=HTMLResponse, include_in_schema=False)
        async def placeholder() -> str:
            return (
                "<!doctype html><title>riderlive</title><h1>riderlive</h1>"
                "<p>The service runs. Frames: <code>/ws/rider</code>; API: <a href='/docs'>/docs</a>; "
                "<a href='/metrics'>/metrics</a>.</p>"
            )

    return app
