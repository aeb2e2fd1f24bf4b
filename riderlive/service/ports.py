"""The narrow ports the web side's components are handed instead of the whole service.

:class:`~riderlive.service.runtime.Service` implements them (``mypy --strict`` checks it
where it builds the components); tests implement them with fakes: a tick that records
what it is told and a clock they set (``tests/service/fakes.py``).

- :class:`TickPort`: the tick as the web side reaches it (input, commands, time, status);
  :class:`~riderlive.realtime.link.TickLink` is the real one.
- :class:`StopPort`: who latches an e-stop (the supervisor).
- :class:`ControlPort`: the arming and e-stop paths; ``devices_api.DevicesPort``,
  ``bus.inbound.InboundPort`` and ``bus.rig.RigPort`` add to it.
- :class:`ServicePort`: what every endpoint reads of the service; :class:`PublishPort`
  (``/ws/rider``) adds to it, and so does ``service.ingest.IngestPort`` (``/ws/horse``,
  ``/ws/saddle``: the arbiter), defined beside the arbiter.
"""

from __future__ import annotations

from collections import Counter
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from collections.abc import Callable

    import numpy as np

    from riderlive.devices.latch import StopSource
    from riderlive.realtime import commands as cmd
    from riderlive.realtime.layout import InputKind
    from riderlive.realtime.link import TickLink
    from riderlive.realtime.shm import SharedBlob
    from riderlive.service.config import ServiceConfig
    from riderlive.service.metrics import ServiceMetrics
    from riderlive.service.supervisor import TickSupervisor
    from riderlive.service.timecodes import ServiceTimecode
    from riderlive.skeleton.rig import Pose


class TickPort(Protocol):
    """The tick, from the web process: engine seconds since ``start`` (``perf_counter`` s)."""

    @property
    def start(self) -> float: ...

    def engine_time(self) -> float: ...

    def push_input(
        self,
        producer: int,
        t: float,
        received: float,
        values: list[float] | np.ndarray,
        kind: InputKind = ...,
        *,
        rebased: bool = ...,
    ) -> None:
        """One validated frame (service units) for the tick; ``received`` in engine seconds;
        ``rebased``: the producer's clock was re-anchored at it (``ClockStep.rebased``)."""

    def input_pending(self, received: float | None) -> None:
        """A frame received at ``received`` (``perf_counter`` seconds) is on its way (None: no longer)."""

    def tell(self, command: cmd.Command) -> bool:
        """A command the tick may miss while down (False: not sent)."""

    def status(self) -> dict[str, Any]:
        """The tick's latest status."""

    @property
    def status_blob(self) -> SharedBlob:
        """Where the tick writes it (its ``version`` changes with each write)."""
        ...


class StopPort(Protocol):
    def estop(self, source: StopSource) -> float:
        """Latch an e-stop of every device; the request time (``perf_counter`` s)."""


class PosesPort(Protocol):
    def rider(self, record: np.ndarray) -> Pose: ...

    def horse(self, record: np.ndarray) -> Pose: ...


class ServicePort(Protocol):
    """What every endpoint reads of the service."""

    @property
    def config(self) -> ServiceConfig: ...

    @property
    def session(self) -> str: ...

    @property
    def metrics(self) -> ServiceMetrics: ...

    @property
    def link(self) -> TickPort: ...

    @property
    def timecode(self) -> ServiceTimecode:
        """Each record's and each producer's SMPTE label (``service/timecodes.py``)."""
        ...


class StopCounts(Protocol):
    @property
    def estops(self) -> Counter[tuple[str, bool]]:
        """E-stop requests by (source label, authorized) (``devices_api.DeviceMetrics``)."""
        ...

    @property
    def refusals(self) -> Counter[tuple[str, str]]:
        """Refused device requests by (action, reason) (``riderlive_device_refusals_total``)."""
        ...


class PublishPort(ServicePort, Protocol):
    """What ``/ws/rider`` reads of the service."""

    @property
    def device_metrics(self) -> StopCounts: ...

    @property
    def poses(self) -> PosesPort: ...

    @property
    def extra_channels(self) -> tuple[str, ...]: ...

    @property
    def supervisor(self) -> StopPort: ...


class ControlPort(Protocol):
    """What the arming and e-stop paths (REST's device routes, NATS control and producers)
    use of the service: the real link and supervisor, and the arm checks."""

    @property
    def config(self) -> ServiceConfig: ...

    @property
    def metrics(self) -> ServiceMetrics: ...

    @property
    def link(self) -> TickLink: ...

    @property
    def supervisor(self) -> TickSupervisor: ...

    @property
    def arm_checks(self) -> list[Callable[[], str | None]]:
        """Each may refuse an arm with a reason (e.g. no stage heartbeat: ``bus.rig``)."""
        ...
