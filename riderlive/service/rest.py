"""REST bodies and how bad ones are answered: never a 500, never an echo of a file.

- Every body is a pydantic model that refuses NaN, infinities and unknown fields; names (takes,
  presets) follow :data:`riderlive.names.NAME_PATTERN`, so they are never paths.
- A body that fails validation gets **422** with ``{"detail": [{"loc", "msg", "type"}]}``:
  where and why, without the offending input (it may be NaN, which JSON cannot carry,
  or something the client should not see echoed).
- A body larger than ``limit`` bytes gets **413** (:class:`RestGuard`; read and dropped
  up to 16 x the limit, so the answer arrives and the connection stays usable); a
  chunked one is cut off at the limit (400).
- Every 4xx answer is counted by status (``riderlive_rest_rejected_total``).
"""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Sequence
from typing import Annotated, Literal

import orjson
import pydantic
from fastapi import Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from riderlive.horse import GAITS, TerrainConfig, gait_speed
from riderlive.names import NAME_PATTERN

Name = Annotated[str, pydantic.Field(min_length=1, max_length=64, pattern=NAME_PATTERN)]
"""A take or preset name: 1-64 of ``A-Z a-z 0-9 _ -``, starting with a letter or digit."""


class Body(pydantic.BaseModel):
    """Base of request bodies: finite numbers only, no unknown fields (a typo is an error)."""

    model_config = pydantic.ConfigDict(allow_inf_nan=False, extra="forbid")


class ProceduralSource(Body):
    kind: Literal["procedural"]
    gait: str | None = None
    speed: float | None = pydantic.Field(default=None, ge=0.0, le=20.0)
    terrain: TerrainConfig | None = None
    """The ground from now on (``horse.terrain.join``: the slope eases in over 5 m); unset: unchanged."""

    @pydantic.field_validator("gait")
    @classmethod
    def _gait(cls, value: str | None) -> str | None:
        if value is not None and value not in GAITS:
            raise ValueError(f"unknown gait; choose one of {', '.join(GAITS)}")
        return value

    @pydantic.model_validator(mode="after")
    def _speed_of_its_gait(self) -> ProceduralSource:
        if self.speed is not None:
            if self.gait is None:
                raise ValueError("speed needs its gait: give both")
            gait_speed(self.gait, self.speed)  # ValueError naming the gait's range
        return self


class ReplaySource(Body):
    kind: Literal["replay"]
    take: Name
    loop: bool = False
    from_tc: str | None = pydantic.Field(default=None, max_length=11, pattern=r"^\d{2}:\d{2}:\d{2}[:;.,]\d{2}$")
    """Start at this timecode of the take (``HH:MM:SS:FF``, ``;`` at drop-frame rates: docs/timecode.md)."""


class LiveSource(Body):
    kind: Literal["live"]


SourceRequest = Annotated[ProceduralSource | ReplaySource | LiveSource, pydantic.Field(discriminator="kind")]


class PerformRequest(Body):
    move: str = pydantic.Field(min_length=1, max_length=64)


class PresetRequest(Body):
    name: Name


class AnimatorBody(Body):
    offsets: dict[str, float] = pydantic.Field(default_factory=dict)
    gains: dict[str, float] = pydantic.Field(default_factory=dict)


class RecordStart(Body):
    name: Name | None = None
    """None: ``take-YYYYmmdd-HHMMSS`` (with ``-2``, ``-3``... if taken)."""
    overwrite: bool = False
    """Replace an existing take of that name, once the new one is complete (else 409)."""


async def invalid_request(request: Request, exc: Exception) -> JSONResponse:
    """422 naming where and why, never echoing the input."""
    errors = exc.errors() if isinstance(exc, RequestValidationError) else []
    detail = [
        {
            "loc": [part if isinstance(part, int) else str(part) for part in error.get("loc", ())],
            "msg": str(error.get("msg", "invalid")),
            "type": str(error.get("type", "value_error")),
        }
        for error in errors
    ]
    return JSONResponse({"detail": detail}, status_code=422)


class BodyTooLarge(Exception):
    """A request body beyond the limit (raised from ``receive``)."""


class RestGuard:
    """ASGI middleware: request bodies of at most ``limit`` bytes; every 4xx counted in ``rejected``.

    ``larger``: ``(path regex, limit)`` pairs for the few routes that take files (uploads).
    """

    def __init__(
        self, app: ASGIApp, limit: int, rejected: Counter[int], larger: Sequence[tuple[str, int]] = ()
    ) -> None:
        self.app = app
        self.limit = limit
        self.rejected = rejected
        self.larger = [(re.compile(pattern), size) for pattern, size in larger]

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def counted(message: Message) -> None:
            if message["type"] == "http.response.start" and 400 <= message["status"] < 500:
                self.rejected[message["status"]] += 1
            await send(message)

        limit = next((size for pattern, size in self.larger if pattern.match(scope.get("path", ""))), self.limit)
        length = dict(scope.get("headers", ())).get(b"content-length")
        if length is not None and (not length.isdigit() or int(length) > limit):
            # A body up to 16 x the limit is read and dropped, so the answer is not lost to
            # a TCP reset and the connection stays usable; a larger one closes it.
            drained = length.isdigit() and int(length) <= 16 * limit
            while drained and (await receive()).get("more_body", False):
                pass
            body = orjson.dumps({"detail": f"request body over {limit} bytes"})
            headers = [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]
            if not drained:
                headers.append((b"connection", b"close"))
            await counted({"type": "http.response.start", "status": 413, "headers": headers})
            await send({"type": "http.response.body", "body": body})
            return
        received = 0

        async def limited() -> Message:
            nonlocal received
            message = await receive()
            received += len(message.get("body", b""))
            if received > limit:
                raise BodyTooLarge(f"request body over {limit} bytes")
            return message

        await self.app(scope, limited, counted)
