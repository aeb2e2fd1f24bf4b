"""The service's typed configuration (``riderlive serve --config FILE``).

Every key has a default, so ``riderlive serve`` with no file runs the procedural
horse on 127.0.0.1:8000. See ``config/service.example.toml`` for a commented file.
"""

from __future__ import annotations

import ipaddress
from pathlib import Path
from typing import Literal

import pydantic

from riderlive.bus.config import NatsSection
from riderlive.channels import Kind, is_known
from riderlive.configfile import StrictModel, load
from riderlive.horse import DEFAULT_SCALE, GAITS, TerrainConfig, gait_speed
from riderlive.ranges import KIND_DEFAULTS, Range, Ranges, check_range
from riderlive.saddle.pose import SaddlePoint
from riderlive.timecode import Rate
from riderlive.vmc.target import parse_target


class ServerSection(StrictModel):
    host: str = "127.0.0.1"
    port: int = pydantic.Field(default=8000, ge=0, le=65535)
    cors_origins: list[str] = pydantic.Field(default_factory=list)
    log_level: Literal["critical", "error", "warning", "info", "debug"] = "info"
    shutdown_timeout: float = pydantic.Field(default=5.0, gt=0.0, le=60.0)
    nice: int = pydantic.Field(default=0, ge=-20, le=19)
    """Scheduling niceness of the web process (negative needs privileges; falls back with a warning)."""
    realtime_priority: int = pydantic.Field(default=10, ge=0, le=49)
    """SCHED_FIFO priority of the web process, below the tick's 50 (0: off, normal scheduling).
    On a busy machine this is what keeps ingest-to-send within a tick + 1 ms and a failover's
    first frame within 50 ms (docs/performance.md). Where the host does not permit it (no root,
    no rtprio limit) the web process runs at normal priority with a warning at start; its
    children (the tick, the spare, the guardian) and its worker threads (bakes, uploads) do not
    inherit it."""
    loop: Literal["auto", "asyncio", "uvloop"] = "auto"
    """The web process's event loop: ``auto`` is uvloop when installed (it is a dependency), else asyncio."""


class SecuritySection(StrictModel):
    token: str | None = None
    """Required for ingest and control when bound to a non-loopback address."""
    require_token: bool | None = None
    """None: required exactly when ``host`` is not a loopback address."""
    publish_requires_token: bool = False

    @pydantic.field_validator("token")
    @classmethod
    def _token_chars(cls, value: str | None) -> str | None:
        if value is not None and (len(value) < 8 or not all(c.isalnum() or c in "-_." for c in value)):
            raise ValueError("must be at least 8 characters of A-Z a-z 0-9 - _ . (it travels in a subprotocol)")
        return value


class TickSection(StrictModel):
    rate: float = pydantic.Field(default=120.0, ge=30.0, le=1000.0)
    realtime_priority: bool = True
    spin: float | None = pydantic.Field(default=None, ge=0.0, le=0.005)
    """Seconds the tick spins before each deadline; unset: 0.25 ms at SCHED_FIFO, else 1 ms."""
    isolation: Literal["process", "thread"] = "process"
    """``process``: the tick in its own process (the design). ``thread``: in the web
    process, sharing its GIL; only as a baseline for benchmarks."""
    length_scale: float = pydantic.Field(default=DEFAULT_SCALE, gt=0.0)
    """Thesis rig units per service length unit (25 = the service speaks metres)."""
    preset: str = "kuhnel2003"
    preset_dirs: list[str] = pydantic.Field(default_factory=list)
    """Directories of the deployment's presets; ``PUT /api/preset`` loads only from these
    and the shipped ``config/presets`` (by name, never by path)."""
    param_blend_time: float = pydantic.Field(default=0.5, ge=0.0, le=10.0)
    """Seconds over which a change of preset, parameters or animator layer blends in."""
    spare: bool = True
    """Keep a warm spare tick beside the running one (``realtime/spare.py``): a failover in
    ~20 ms. Off: one tick process less (~175 MB resident, ~1.6 s of CPU per start and per
    failover), and a failover is a cold start (seconds; tens of seconds on a busy host),
    so the hang threshold stays at ``hang_floor_cold`` while no device moves
    (docs/deployment.md, "A tick that dies or stalls"). Ignored with ``isolation = "thread"``."""
    spare_nice: int = pydantic.Field(default=10, ge=0, le=19)
    """Nice value of the warm spare tick's warm-up (``realtime/spare.py``): higher takes less
    of the running tick's CPU on a busy host and warms the spare later."""
    hang_ticks: float = pydantic.Field(default=5.0, ge=2.0, le=1000.0)
    """A tick whose heartbeat is older than this many periods is hung: killed and
    restarted (its devices stay safe and are not re-armed). Raise it on a machine
    without real-time priority at high rates (docs/architecture.md, "Supervision")."""
    hang_floor: float = pydantic.Field(default=0.25, ge=0.0, le=60.0)
    """Without real-time priority the hang threshold is at least this (seconds): a loaded
    machine stalls a normal-priority process for tens of milliseconds."""
    hang_floor_realtime: float = pydantic.Field(default=0.03, ge=0.0, le=60.0)
    """With real-time priority the hang threshold is at least this (seconds): even a
    SCHED_FIFO tick is late by ~10 ms now and then on a busy 2-core machine."""
    hang_floor_cold: float = pydantic.Field(default=2.0, ge=0.0, le=60.0)
    """While no warm spare waits and no device moves the hang threshold is at least this
    (seconds): a failover would be a cold start (5-27 s at load 20-25 in the soak), and a
    moving device has the guardian's ``tick_timeout`` anyway."""
    restart_backoff: float = pydantic.Field(default=0.25, gt=0.0, le=60.0)
    """Seconds before restarting a dead tick, doubled per failure in a row (up to 30 s)."""
    phase_lock: bool = True
    """Move the tick's deadlines (by at most 2 % of a period a tick, the rate unchanged) to
    just after the driving producer's frames arrive, when they come steadily at the tick's
    rate or a whole multiple or fraction of it (``realtime/phase_lock.py``, docs/performance.md)."""
    phase_margin: float = pydantic.Field(default=0.0003, ge=0.0, le=0.005)
    """Seconds: the least time from a frame's expected arrival to the deadline that takes it
    (the measured arrival jitter when larger); less than half a period."""

    @pydantic.field_validator("phase_margin")
    @classmethod
    def _margin_within_period(cls, value: float, info: pydantic.ValidationInfo) -> float:
        rate = info.data.get("rate")
        if rate is not None and value >= 0.5 / rate:
            raise ValueError(f"must be less than half a period: 0 <= phase_margin < {0.5 / rate:.6f} s at {rate:g} Hz")
        return value


class InputSection(StrictModel):
    delay: float = pydantic.Field(default=0.01, ge=0.0, le=1.0)
    hold: float = pydantic.Field(default=0.25, ge=0.0, le=5.0)
    ease_time: float = pydantic.Field(default=1.0, ge=0.0, le=30.0)
    blend_time: float = pydantic.Field(default=0.5, ge=0.0, le=30.0)
    producer_timeout: float = pydantic.Field(default=0.5, gt=0.0, le=30.0)
    """A producer silent this long loses control to another one."""
    max_message_bytes: int = pydantic.Field(default=65536, ge=256, le=16 * 1024 * 1024)
    max_rate: float = pydantic.Field(default=2000.0, gt=0.0)
    """Frames per second per producer connection; faster frames are rejected."""
    max_errors: int = pydantic.Field(default=100, ge=1)
    """Rejected frames within ``error_window`` before the connection is closed."""
    error_window: float = pydantic.Field(default=10.0, gt=0.0)
    clock_jump: float = pydantic.Field(default=0.5, ge=0.05, le=60.0)
    """A producer clock that moves this many seconds more or less than the service's
    between two frames starts a new stream segment (docs/protocol.md)."""
    saddle: bool = True
    """Accept saddle producers (``/ws/saddle``, the stage's saddle subjects). Off: the
    tick never drives from a saddle stream, so no saddle estimate exists, and a device
    that consumes it is refused at start (``riderlive.tickframe.MissingPart``)."""


class SourceSection(StrictModel):
    kind: Literal["live", "procedural"] = "live"
    """``live``: producers drive when present; ``procedural``: the procedural horse is pinned."""
    fallback_procedural: bool = True
    """In ``live``: the procedural horse runs while no producer drives."""
    resume_after: float = pydantic.Field(default=2.0, ge=0.0, le=600.0)
    gait: str = "trot"
    speed: float | None = pydantic.Field(default=None, ge=0.0, le=20.0)
    """m/s within the gait's range; unset: the gait's own speed."""
    seed: int | None = None
    terrain: TerrainConfig | None = None
    """``[source.terrain]``: the ground the procedural horse runs on, one of ``slope`` (deg) or
    ``profile`` (``[[distance m, slope deg], ...]``, from where it starts); unset: flat and level."""

    @pydantic.field_validator("gait")
    @classmethod
    def _known_gait(cls, value: str) -> str:
        if value not in GAITS:
            raise ValueError(f"unknown gait; choose one of {', '.join(GAITS)}")
        return value

    @pydantic.field_validator("speed")
    @classmethod
    def _gait_allows(cls, value: float | None, info: pydantic.ValidationInfo) -> float | None:
        gait = info.data.get("gait")
        if value is not None and gait is not None:
            gait_speed(gait, value)  # ValueError naming the gait's range
        return value


class RangesSection(StrictModel):
    """Plausible channel ranges (``riderlive.ranges``): metres, degrees, unitless."""

    channels: dict[str, Range] = pydantic.Field(default_factory=dict)
    """Channel name or ``fnmatch`` pattern -> [low, high]; wins over the shipped defaults."""
    length: Range = KIND_DEFAULTS[Kind.TRANSLATION]
    rotation: Range = KIND_DEFAULTS[Kind.ROTATION]
    unitless: Range = KIND_DEFAULTS[Kind.ATTRIBUTE]

    @pydantic.field_validator("channels")
    @classmethod
    def _known(cls, value: dict[str, Range]) -> dict[str, Range]:
        for key, bounds in value.items():
            if not is_known(key) and not any(c in key for c in "*?["):
                raise ValueError(f"unknown channel {key!r} (a name of riderlive.channels or a pattern)")
            check_range(key, bounds)
        return value

    @pydantic.field_validator("length", "rotation", "unitless")
    @classmethod
    def _valid(cls, value: Range) -> Range:
        return check_range("range", value)

    def ranges(self) -> Ranges:
        kinds = {Kind.TRANSLATION: self.length, Kind.ROTATION: self.rotation, Kind.ATTRIBUTE: self.unitless}
        return Ranges(overrides=dict(self.channels), kinds=kinds)


class PublishSection(StrictModel):
    send_timeout: float = pydantic.Field(default=2.0, gt=0.0, le=60.0)
    """A client whose send takes longer than this is cut off."""
    max_clients: int = pydantic.Field(default=256, ge=1)
    send_buffer_bytes: int = pydantic.Field(default=65536, ge=4096, le=16 * 1024 * 1024)
    """Kernel send buffer per client (SO_SNDBUF): how much may queue for a slow reader."""


class TakesSection(StrictModel):
    directory: str = "takes"
    flush_interval: float = pydantic.Field(default=0.25, gt=0.0, le=1.0)
    """Seconds between writes of a take: a killed server loses at most this plus one tick."""
    fit_timeout: float = pydantic.Field(default=600.0, gt=0.0, le=3600.0)
    """Seconds a fit of a take (``POST /api/takes/NAME/fit``) may run before it is killed."""


class RigSection(StrictModel):
    file: str | None = None
    port: str | None = None
    park_timeout: float = pydantic.Field(default=5.0, gt=0.0, le=60.0)
    arm: bool = False
    """Arm the rig once it is connected, at start only (``serve --arm``). Unattended use
    only: the rig moves with nobody confirming it (docs/hardware.md)."""
    rate_policy: Literal["divide", "refuse"] = "divide"
    """A rig validated (``bus.tick_hz``) below ``tick.rate``: drive it every n-th tick,
    or refuse to start."""


class PlatformSection(StrictModel):
    """``[platform]`` of the service configuration (docs/configuration.md)."""

    file: str | None = None
    """A platform file, or a shipped platform's name (``config/platforms``); unset: no platform."""
    port: str | None = None
    """The firmware's serial port (``riderlive firmware-emu`` prints its pty)."""
    device: str | None = pydantic.Field(default=None, min_length=1, max_length=16, pattern=r"^[!-~]+$")
    """The firmware's own name, checked at connect and sent with ARM (default: what it says)."""
    heartbeat_ms: int = pydantic.Field(default=200, ge=20, le=1000)
    """The firmware's dead-man timeout (CONFIG): it parks by itself after this much silence."""
    rate_policy: Literal["divide", "refuse"] = "divide"
    """A service ticking faster than the firmware's control rate: drive it every n-th tick, or refuse."""

    @pydantic.model_validator(mode="after")
    def _port_with_file(self) -> PlatformSection:
        if self.file and not self.port:
            raise ValueError("platform.port is required with platform.file (the firmware's serial port)")
        return self


class GuardianSection(StrictModel):
    """The dead-man process that parks the devices when the tick or the web process dies."""

    enabled: bool = True
    tick_timeout: float = pydantic.Field(default=0.5, ge=0.02, le=10.0)
    """Seconds without a tick heartbeat before the guardian acts on its own, for when the
    web process is frozen too (a live web process kills a hung tick sooner, after
    ``tick.hang_ticks``, and the guardian sees that death at once)."""
    web_timeout: float = pydantic.Field(default=2.0, ge=0.1, le=60.0)
    """Seconds without a web-process heartbeat before the guardian stops everything."""
    give_up: float = pydantic.Field(default=10.0, ge=1.0, le=600.0)
    """With the web process gone, seconds the guardian repeats an unconfirmed outputs-off
    (a silent bus) before it exits, leaving the servos to their Bus Watchdog."""
    priority: int = pydantic.Field(default=20, ge=0, le=49)
    """SCHED_FIFO priority of the guardian and its standby once their imports are paid (0:
    normal scheduling): above the web process's 10, below the tick's 50, so that neither a
    busy web process nor the host's other work starves the dead-man's heartbeat (the tick
    takes a guardian silent for ``GUARDIAN_HANG_S`` for hung and parks). Where the host
    does not permit SCHED_FIFO it runs at normal priority with a warning."""


class HostSection(StrictModel):
    """``[host]``: what riderlive changes on its host for the serial devices (docs/hardware.md "A busy host")."""

    kernel_workers_priority: int = pydantic.Field(default=0, ge=0, le=9)
    """SCHED_FIFO priority for the kernel's unbound workers (``kworker/u*``, which carry the
    servo bytes through the tty layer), kept raised while the service runs
    (``service/kworkers.py``); 0: off. Below the web process's 10; needs root (CAP_SYS_NICE)."""


class PhysicsSection(StrictModel):
    tail: bool = False
    """Run the horse's tail and the rider's braid in the tick and publish ``tail_NN.*`` /
    ``braid_NN.*``. Off by default: the compiled kernels take 10-20 s to compile on a
    cold cache (once per checkout; `riderlive serve --tail` turns it on)."""
    file: str | None = None
    """Physics TOML (default ``config/physics/tail.toml``)."""


class VmcSection(StrictModel):
    """VMC out (``docs/vmc.md``): the rider as a VMC performer, the horse as a generic skeleton."""

    target: str | None = None
    """``HOST:PORT`` of the marionette (EVMC4U, VMC4UE, VRM4U, VMC4B; usually port 39539); unset: off."""
    horse_target: str | None = None
    """``HOST:PORT`` for the horse (another port or host); unset: the horse is not sent."""
    rate: float = pydantic.Field(default=60.0, gt=0.0, le=1000.0)
    """Bundles per second: every ``round(tick.rate / rate)``-th tick."""
    local_port: int = pydantic.Field(default=0, ge=0, le=65535)
    """The UDP port we send from (0: any free port)."""

    @pydantic.field_validator("target", "horse_target")
    @classmethod
    def _host_port(cls, value: str | None) -> str | None:
        if value is not None:
            parse_target(value)
        return value


class TimecodeSection(StrictModel):
    """SMPTE timecode of frames, takes and exports (docs/timecode.md)."""

    rate: Rate = Rate.FPS_25
    """One of 23.976, 24, 25, 29.97df, 30, 48, 50, 59.94df, 60; a producer's ``tc`` must be at this rate."""
    offset: float = pydantic.Field(default=0.0, ge=-86400.0, le=86400.0)
    """Seconds added to the host clock's time of day when no producer (or stage) gives the timecode."""
    clock: Literal["utc", "local"] = "local"
    """The host clock's time of day: local (with its time zone) or UTC."""
    stage_timeout: float = pydantic.Field(default=2.0, gt=0.0, le=60.0)
    """Seconds a stage heartbeat's timecode stays the reference after the last one arrived."""


class FoxgloveSection(StrictModel):
    """The Foxglove WebSocket server (docs/foxglove.md); also ``serve --foxglove PORT``."""

    port: int | None = pydantic.Field(default=None, ge=0, le=65535)
    """Unset: off; 0: any free port. It listens on ``server.host`` and has no token: read-only data."""
    tf_rate: float = pydantic.Field(default=30.0, gt=0.0, le=1000.0)
    """``/tf`` (both skeletons) messages per second (every ``round(tick.rate / tf_rate)``-th tick)."""
    backlog: int = pydantic.Field(default=1024, ge=16, le=1_000_000)
    """Messages the SDK queues per client before it drops that client's messages."""


class ServiceConfig(StrictModel):
    server: ServerSection = ServerSection()
    security: SecuritySection = SecuritySection()
    tick: TickSection = TickSection()
    input: InputSection = InputSection()
    source: SourceSection = SourceSection()
    publish: PublishSection = PublishSection()
    takes: TakesSection = TakesSection()
    rig: RigSection = RigSection()
    platform: PlatformSection = PlatformSection()
    physics: PhysicsSection = PhysicsSection()
    ranges: RangesSection = RangesSection()
    vmc: VmcSection = VmcSection()
    guardian: GuardianSection = GuardianSection()
    host: HostSection = HostSection()
    saddle: SaddlePoint = SaddlePoint()
    """Where the saddle point sits on the horse's back (docs/saddle.md): the published
    saddle pose's point, and the point a ``/ws/saddle`` stream is taken to measure."""
    timecode: TimecodeSection = TimecodeSection()
    foxglove: FoxgloveSection = FoxgloveSection()
    nats: NatsSection = NatsSection()
    """Join a stage over NATS (docs/deployment.md); unset ``url``: brokerless."""

    @pydantic.model_validator(mode="after")
    def _token_when_required(self) -> ServiceConfig:
        if self.token_required and not self.security.token:
            raise ValueError(
                f"server.host {self.server.host!r} is not a loopback address: set security.token "
                "(or security.require_token = false to run open, at your own risk)"
            )
        return self

    @property
    def arming_token(self) -> str | None:
        """Arming needs the token whenever one is configured, loopback or not."""
        return self.security.token

    @property
    def token_required(self) -> bool:
        if self.security.require_token is not None:
            return self.security.require_token
        return not is_loopback(self.server.host)


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def load_config(path: str | Path | None) -> ServiceConfig:
    """The config in ``path``, or the defaults."""
    return ServiceConfig() if path is None else load(ServiceConfig, path)
