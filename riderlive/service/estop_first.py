"""``POST /api/estop`` before anything else: the latch is set by the outermost ASGI layer.

Every other layer (the body limit, CORS, routing, the token check, validation, the
access log) runs after the e-stop is latched in shared memory and the tick is woken.
This layer's first act is the latch's one store that every goal write checks
(:meth:`riderlive.devices.latch.StopLatch.request`); the request's arrival
(``received_at``) is the time read right after that store, so no goal write that
begins after the arrival can pass its at-write check (a write stamps its beginning
before its check). ``latched_at`` is when the latch returned: a goal write that was
already on its way has left, and the tick has been woken.

Decision (docs/hardware.md, "E-stop without the token"): an e-stop is **never locked**.
Whoever can reach the service may stop the rig, token or not, loopback or not; the
route then tells the two apart, counts an e-stop without the token separately
(``riderlive_estop_requests_by_source_total{authorized="no"}``) and logs the client's
address. Reset and arm still need the token, so a stop from the network can cost an
operator a reset, never start motion. A network is not a panel: this is not the
e-stop near people, which must cut servo power in hardware.
"""

from __future__ import annotations

import time
from collections.abc import Callable, MutableMapping
from typing import Any

from riderlive.devices.latch import StopSource

ESTOP_PATH = "/api/estop"
STATE_KEY = "riderlive.estop"
"""Where ``(received_at, latched_at)`` (perf_counter s, see above) wait for the route, in the scope's state."""


class EStopFirst:
    """ASGI middleware: latch (``estop(StopSource.REST)``) on ``POST /api/estop``, then pass on."""

    def __init__(self, app: Any, estop: Callable[[StopSource], float]) -> None:
        self.app = app
        self.estop = estop

    async def __call__(self, scope: dict[str, Any], receive: Any, send: Any) -> None:
        if scope["type"] == "http" and scope["path"] == ESTOP_PATH and scope["method"] == "POST":
            received = self.estop(StopSource.REST)  # the store first, then the time
            latched = time.perf_counter()
            scope.setdefault("state", {})[STATE_KEY] = (received, latched)
        await self.app(scope, receive, send)


def stamps(scope: MutableMapping[str, Any]) -> tuple[float, float] | None:
    """``(received_at, latched_at)`` set by :class:`EStopFirst` for this request (None: not through it)."""
    value = scope.get("state", {}).get(STATE_KEY)
    return None if value is None else (float(value[0]), float(value[1]))
