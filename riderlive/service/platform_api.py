"""REST and metrics of the motion platform (the lifecycle's own routes are in devices_api).

    GET   /api/platform                               its full status (firmware, link, actuators)
    PATCH /api/platform {"intensity": 60, ...}        live cueing parameters, blended in

The PATCH body takes the platform's device name (optional when there is one platform) and
any of the cueing parameters of ``riderlive.platform.mechanism.cueing_params.CueingParams`` (ranges checked
here: 422; checked again against the whole set by the tick: 422 ``bad_config``). It needs
the token whenever one is configured, like arming: it changes how far the platform moves
(checked before the body by ``auth.WriteGuard``, ``auth.WRITE_RULES``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import pydantic
from fastapi import FastAPI, HTTPException, Request

from riderlive.devices.lifecycle import REFUSAL_STATUS, Refusal
from riderlive.names import NAME_PATTERN
from riderlive.prometheus import Exposition, Kind, sample
from riderlive.realtime import commands as cmd

if TYPE_CHECKING:
    from riderlive.service.runtime import Service

LINK_ERRORS = ("rx_cobs", "rx_short", "rx_oversize", "rx_crc", "rx_version", "rx_type", "rx_length", "rx_stale")
"""Frames dropped by a check (docs/platform-link.md), per side; ``rx_gap`` counts frames lost in between."""


class PlatformTune(pydantic.BaseModel):
    """A PATCH body: which platform, and the cueing parameters to change (units of CueingParams)."""

    model_config = pydantic.ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    device: str | None = pydantic.Field(default=None, pattern=NAME_PATTERN)
    intensity: float | None = pydantic.Field(default=None, ge=0.0, le=100.0)
    drift_cutoff_hz: float | None = pydantic.Field(default=None, ge=0.01, le=0.5)
    washout_translation_hz: float | None = pydantic.Field(default=None, ge=0.1, le=2.5)
    washout_rotation_hz: float | None = pydantic.Field(default=None, ge=0.1, le=2.5)
    washout_hold_s: float | None = pydantic.Field(default=None, ge=0.0, le=10.0)
    knee: float | None = pydantic.Field(default=None, ge=0.2, le=0.95)
    share: float | None = pydantic.Field(default=None, gt=0.0, le=1.0)
    tilt_gain: float | None = pydantic.Field(default=None, ge=0.0, le=1.0)
    tilt_rate_dps: float | None = pydantic.Field(default=None, gt=0.0, le=60.0)
    tilt_max_deg: float | None = pydantic.Field(default=None, ge=0.0, le=30.0)
    blend_s: float | None = pydantic.Field(default=None, ge=0.0, le=10.0)
    by: str | None = pydantic.Field(default=None, max_length=32, pattern=r"^[A-Za-z0-9 _.-]+$")

    def changes(self) -> dict[str, Any]:
        return self.model_dump(exclude_none=True, exclude={"device", "by"})


def platform_status(service: Service) -> dict[str, Any] | None:
    status: dict[str, Any] | None = service.link.status().get("platform")
    return status


def add_platform_routes(app: FastAPI, service: Service, observe: list[Any]) -> None:
    """The routes; ``observe``: the app's dependencies for read-only calls."""

    def refuse(reason: Refusal, message: str) -> HTTPException:
        service.device_metrics.refusals[("tune", reason.value)] += 1
        return HTTPException(REFUSAL_STATUS.get(reason, 409), {"refusal": reason.value, "message": message})

    @app.get("/api/platform", dependencies=observe, summary="The platform: state, firmware, link, actuators")
    async def get_platform() -> dict[str, Any]:
        status = platform_status(service)
        if status is None:
            raise refuse(Refusal.UNKNOWN_DEVICE, "no platform is configured ([platform] file and port)")
        return status

    @app.patch("/api/platform", summary="Live cueing parameters of the platform (intensity 0-100 %, ...)")
    async def tune_platform(request: Request, body: PlatformTune) -> dict[str, Any]:
        changes = body.changes()
        if not changes:
            raise HTTPException(422, {"refusal": Refusal.BAD_CONFIG.value, "message": "no parameter to change"})
        name = body.device or (platform_status(service) or {}).get("name")
        if not name:
            raise refuse(Refusal.UNKNOWN_DEVICE, "no platform is configured ([platform] file and port)")
        host = request.client.host if request.client else "?"
        by = f"rest {host}" + (f" ({body.by})" if body.by else "")
        reply: cmd.Reply = await service.supervisor.ask(lambda r: cmd.Tune(str(name), changes, by, r))
        if not reply.ok:
            raise refuse(Refusal(reply.refusal or Refusal.NOT_READY), reply.message)
        return {"ok": True, "device": name, "changes": changes, "message": reply.message}


def render_platform_metrics(service: Service) -> str:
    """Prometheus text: workspace use, limits hit, the link's dropped frames both sides."""
    status = platform_status(service)
    if not status or "platform" not in status:
        return ""
    name = str(status.get("name", "platform"))
    p = status["platform"]
    out = Exposition()
    out.family(
        "riderlive_platform_workspace_use",
        Kind.GAUGE,
        "Largest actuator closeness to a soft limit (0 mid-range, 1 at it).",
        [sample("riderlive_platform_workspace_use", float(p.get("workspace_use", 0.0)), {"device": name})],
    )
    limits = [
        sample("riderlive_platform_limits_total", int(value), {"device": name, "limit": limit})
        for limit, value in sorted((p.get("limits_hit") or {}).items())
    ]
    out.family("riderlive_platform_limits_total", Kind.COUNTER, "Frames in which a limit acted, by limit.", limits)
    host = (p.get("link") or {}).get("counters") or {}
    device = ((p.get("firmware") or {}).get("counters")) or {}
    kinds = {
        "host": (*LINK_ERRORS, "rx_gap", "silences", "port_lost"),
        "device": (*LINK_ERRORS, "rx_gap", "deadman", "clipped", "limited", "tx_dropped"),
    }
    link = [
        sample(
            "riderlive_platform_link_total", int(counters.get(kind, 0)), {"device": name, "side": side, "kind": kind}
        )
        for side, counters in (("host", host), ("device", device))
        for kind in (kinds[side] if counters or side == "host" else ())
    ]
    help_text = "Platform link events by side (host, device) and kind."
    out.family("riderlive_platform_link_total", Kind.COUNTER, help_text, link)
    return out.text()
