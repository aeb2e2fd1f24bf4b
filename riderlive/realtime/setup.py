"""What the tick process is started with: :class:`TickSetup`, built by the web process and
pickled into the spawned tick (``riderlive.realtime.link``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from riderlive.devices.registry import DeviceSpec
from riderlive.horse import TerrainConfig
from riderlive.realtime.core import Mode, Timing
from riderlive.realtime.record import RecordLayout
from riderlive.rules.animator import AnimatorLayer
from riderlive.rules.params import RuleParams
from riderlive.saddle.pose import SaddlePoint


@dataclass(frozen=True)
class TickSetup:
    """Everything the tick process needs, picklable for a spawned process."""

    rate: float
    start: float
    """perf_counter value that is engine time 0 (CLOCK_MONOTONIC, shared by processes)."""
    timing: Timing
    params: RuleParams
    animator: AnimatorLayer
    length_scale: float
    gait: str = "trot"
    speed: float | None = None
    """m/s; None: the gait's own speed."""
    seed: int | None = None
    terrain: TerrainConfig | None = None
    """The procedural horse's ground (None: flat and level)."""
    mode: Mode = Mode.INPUT
    realtime_priority: bool = True
    spin: float | None = None
    """Seconds spun before each deadline; None: 0.25 ms at SCHED_FIFO, 1 ms otherwise."""
    isolation: str = "process"
    """``process`` (the design) or ``thread`` (in the web process; a baseline for benchmarks)."""
    devices: tuple[DeviceSpec, ...] = ()
    """Devices to drive (planned by the web process: validated, rates fitted)."""
    park_timeout: float = 5.0
    """At shutdown, how long the devices may take to park before the tick stops anyway."""
    generation: int = 1
    """1 for the first tick of a service, +1 per restart after a crash or a hang."""
    arm_on_start: str | None = None
    """``serve --arm``: arm each device once when it first gets to disarmed (first
    generation only; a restarted tick never re-arms)."""
    guardian: bool = False
    """A guardian process watches this tick: arming is refused while it is not running."""
    latch_name: str | None = None
    board_name: str | None = None
    tail: bool = False
    """Run the tail and braid physics (``riderlive.realtime.tail``) and publish their channels."""
    physics_file: str | None = None
    """Physics TOML (None: ``config/physics/tail.toml``)."""
    layout: RecordLayout = field(default_factory=RecordLayout)
    """The output record's layout (``realtime/record.py``): the tail's channels when on, then
    the rider parts after the rider's; the tick refuses to start with another one."""
    shm_names: dict[str, str] = field(default_factory=dict)
    rider_bounds: tuple[tuple[float, ...], tuple[float, ...]] | None = None
    """Lowest and highest value of each rider channel in service units (``riderlive.ranges``)."""
    saddle_point: SaddlePoint = field(default_factory=SaddlePoint)
    """Where the published saddle pose is taken, and where a saddle input's samples are from."""
    phase_lock: bool = True
    """Move the deadlines to just after the driving producer's frames arrive (``realtime/phase_lock.py``)."""
    tunes: dict[str, dict[str, Any]] = field(default_factory=dict)
    """Live parameters applied to devices since start (``Tune``, by device name): a new
    generation applies them to its devices before connecting them."""
    spare: bool = True
    """Keep a warm spare beside the running tick (``tick.spare``); off: every failover is a cold start."""
    spare_nice: int = 10
    """Nice value of the warm spare's warm-up thread (``realtime/spare.py``)."""
    phase_margin: float = 0.0003
    """Seconds: the least time from a frame's expected arrival to the deadline that takes it."""

    @property
    def extra_channels(self) -> tuple[str, ...]:
        """Channels of each output record after the rider's (``layout.extra_channels``)."""
        return self.layout.extra_channels
