"""The ``[nats]`` section of the service's config (``riderlive serve --nats URL --stage S --rig R``).

No ``url``: the service joins no stage and imports no NATS code (the default).
"""

from __future__ import annotations

from typing import Literal

import pydantic

from riderlive.bus.subjects import check_name
from riderlive.configfile import StrictModel

HEARTBEAT_TIMEOUT_S = 1.0
"""Default seconds without a stage heartbeat before an armed rig parks (docs/deployment.md)."""


class NatsSection(StrictModel):
    url: str | None = None
    """``nats://host:4222`` (``tls://`` for TLS; comma-separated servers of a cluster). Unset: no stage."""
    stage: str = "stage"
    rig: str | None = None
    """This rig's name on the stage (required with ``url``); a name already in use is refused."""
    user: str | None = None
    password: str | None = None
    token: str | None = None
    """The broker's auth token (not the service's ``security.token``)."""
    creds: str | None = None
    """A NATS ``.creds`` file (JWT + nkey seed)."""
    tls_ca: str | None = None
    tls_cert: str | None = None
    tls_key: str | None = None
    control_auth: Literal["token", "credentials"] = "token"
    """``token``: control requests follow the REST rules (``security.token`` in the request
    whenever REST would need it). ``credentials``: the broker's permissions decide who
    may publish on ``...control`` (give each operator station its own NATS user)."""
    encoding: Literal["binary", "json"] = "binary"
    """Frames on ``...frame``: the RLF1 binary layout or JSON (docs/protocol.md)."""
    heartbeat_timeout: float = pydantic.Field(default=HEARTBEAT_TIMEOUT_S, ge=0.0, le=30.0)
    """Seconds without the stage heartbeat before an armed rig parks; arming is refused
    meanwhile. 0 turns the stage dead-man off (a rig then ignores the network's health)."""
    status_interval: float = pydantic.Field(default=1.0, gt=0.0, le=60.0)
    """Seconds between status messages (also sent at once on every change)."""
    producer_forget: float = pydantic.Field(default=5.0, gt=0.0, le=600.0)
    """A NATS producer silent this long is forgotten (its stream ends)."""
    connect_timeout: float = pydantic.Field(default=2.0, gt=0.0, le=60.0)

    @pydantic.field_validator("stage", "rig")
    @classmethod
    def _name(cls, value: str | None) -> str | None:
        return None if value is None else check_name(value, "name")

    @pydantic.field_validator("url")
    @classmethod
    def _url(cls, value: str | None) -> str | None:
        if value is not None:
            for server in value.split(","):
                scheme = server.strip().split("://", 1)[0] if "://" in server else ""
                if scheme not in ("nats", "tls", "ws", "wss"):
                    raise ValueError("must be nats://HOST:PORT (or tls://, ws://, wss://), comma-separated")
        return value

    @pydantic.model_validator(mode="after")
    def _rig_with_url(self) -> NatsSection:
        if self.url is not None and self.rig is None:
            raise ValueError("nats.url is set: name this rig (nats.rig or --rig NAME)")
        if (self.tls_cert is None) != (self.tls_key is None):
            raise ValueError("nats.tls_cert and nats.tls_key go together")
        return self
