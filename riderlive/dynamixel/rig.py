"""The servo map of an animatronic rider: which servo follows which rider channel, how.

A rig file (``config/rigs/NAME.toml``) has a ``[bus]`` table and one ``[servos.NAME]``
table per servo. Positions are servo shaft degrees over the encoder's turn
(0 .. 359.9 deg = 0 .. 4095 pulses; 180 deg is the middle). A servo follows its
channel as::

    goal_deg = zero_deg + direction * gain * channel_value

``gain`` is servo degrees per channel unit: per degree for rotation channels, per
metre for translation channels (the linkage ratio: a 14 mm horn moves ~0.24 mm per
degree, i.e. ~4100 deg/m), per unit for attributes. Goals are clamped to
``[min_deg, max_deg]`` (also written to the servo's position-limit registers) and
slew-limited to ``max_speed_dps`` (also the servo's Profile Velocity).

:func:`load_rig` validates a file; every error names the file, the key and the range.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

import pydantic
from pydantic import Field

from riderlive.channels import RIDER_INDEX, RIDER_NAMES
from riderlive.configfile import CONFIG_DIR, ConfigError, StrictModel, read_toml, validate
from riderlive.dynamixel.models import Model, ModelSpec, model_spec
from riderlive.dynamixel.tables import POSITION_RANGE, PULSES_PER_TURN, HardwareError
from riderlive.names import NAME_PATTERN

RIG_DIR = CONFIG_DIR / "rigs"
"""The shipped rig maps (the repository's ``config/rigs``)."""

DEG_PER_PULSE = 360.0 / PULSES_PER_TURN
MIN_DEG = POSITION_RANGE[0] * DEG_PER_PULSE
MAX_DEG = POSITION_RANGE[1] * DEG_PER_PULSE
SDK_BAUDS: tuple[int, ...] = (9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 576000, 921600)
SDK_BAUDS += (1_000_000, 1_152_000, 2_000_000, 2_500_000, 3_000_000, 3_500_000, 4_000_000)
"""Baud rates ``dynamixel_sdk.PortHandler.setBaudRate`` accepts."""

HardwareErrorName = Literal["input_voltage", "overheating", "motor_encoder", "electrical_shock", "overload"]


PARK_SETTLE_SHARE = 0.25
"""The most of ``park_s`` that waits for arrival (the ease keeps at least 3/4 of it)."""


class BusConfig(StrictModel):
    """The serial bus and the timing of the lifecycle (times in seconds unless named)."""

    port: str = "/dev/ttyUSB0"
    baud: int = 1_000_000
    protocol: float = 2.0
    tick_hz: float = Field(100.0, gt=0.0, le=2000.0)
    """The rate the service calls ``tick()``; sizes the setup budget and the watchdog check."""
    read_divider: int = Field(4, ge=1, le=1000)
    """Read present position, temperature and errors every N ticks."""
    fast_sync_read: bool = True
    fast_read_fallback_after: int = Field(10, ge=1)
    """Fast Sync Reads failing in a row (no fast success between) before the plain Sync Read
    takes over; it tries fast again after ``fast_read_retry_s``."""
    fast_read_retry_s: float = Field(30.0, gt=0.0, le=3600.0)
    """After a fallback, try the Fast Sync Read again after this (doubling while it fails)."""
    latency_timer_ms: float = Field(1.0, ge=0.0, le=32.0)
    """The USB adapter's latency timer (FTDI: set it to 1 ms); enters the reply timeout."""
    timeout_margin_ms: float = Field(2.0, gt=0.0, le=200.0)
    """The least a reply may be late beyond wire time + 2 x latency (the SDK uses 2 ms);
    the real allowance is measured from the replies (srtt + 4 rttvar, docs/hardware.md)."""
    max_reply_wait_ms: float = Field(25.0, gt=0.0, le=500.0)
    """The most a reply may be late beyond its wire time, however slow the replies were."""
    reply_budget_s: float = Field(0.1, gt=0.0, le=10.0)
    """How long a servo may stay silent, retried every tick, before the rig faults."""
    bus_error_burst: float = Field(20.0, ge=1.0, le=10_000.0)
    """The error budget: failed reads may outnumber good ones by this much, no more."""
    bus_error_credit: float = Field(1.0, gt=0.0, le=100.0)
    """Failed reads repaid by each good read (1: the bus faults when most reads fail)."""
    setup_retry_s: float = Field(1.0, gt=0.0, le=60.0)
    """How long the start-up steps retry a silent servo before refusing to start."""
    bus_watchdog_ms: int = Field(100, ge=0, le=2540)
    """The servos' Bus Watchdog (98): they stop by themselves after this silence (0 = off)."""
    return_delay_us: int = Field(0, ge=0, le=508)
    soft_start_s: float = Field(2.0, ge=0.0, le=60.0)
    park_s: float = Field(2.0, ge=0.0, le=60.0)
    """A park's whole budget: the ease to the park pose *and* the wait for the servos to
    arrive; torque goes off at the latest ``park_s`` (+ 2 ticks) after the park began."""
    park_settle_s: float = Field(0.3, ge=0.0, le=10.0)
    """The end of ``park_s`` kept for the servos to arrive (read back within
    ``park_tolerance_deg``), at most ``PARK_SETTLE_SHARE`` of it: it comes out of the
    park's budget (the ease is that much shorter), it never adds to it."""
    park_tolerance_deg: float = Field(1.0, gt=0.0, le=10.0)
    """A servo has arrived at its park position within this."""
    close_timeout_s: float = Field(5.0, gt=0.0, le=120.0)
    """``close()`` gives parking this long past ``park_s``, then torques off regardless."""
    setup_share: float = Field(0.5, gt=0.0, le=1.0)
    """Share of a tick the connect/check/configure steps may use (they span several ticks)."""
    reboot_on_error: bool = False
    """At start, REBOOT a servo that reports a hardware error instead of refusing to start."""
    shutdown: tuple[HardwareErrorName, ...] = ("input_voltage", "overheating", "electrical_shock", "overload")
    """Hardware errors on which a servo turns its own torque off (Shutdown, 63)."""

    @pydantic.field_validator("protocol")
    @classmethod
    def _protocol_2(cls, value: float) -> float:
        if value != 2.0:
            raise ValueError("only Dynamixel Protocol 2.0 is supported")
        return value

    @property
    def park_settle_budget_s(self) -> float:
        """The wait for arrival at the end of a park (s): ``park_settle_s``, at most a share of ``park_s``."""
        return min(self.park_settle_s, PARK_SETTLE_SHARE * self.park_s)

    @property
    def park_ramp_s(self) -> float:
        """The ease to the park pose (s): ``park_s`` less the wait for arrival."""
        return self.park_s - self.park_settle_budget_s

    @property
    def tick_s(self) -> float:
        return 1.0 / self.tick_hz

    @property
    def shutdown_mask(self) -> int:
        mask = 0
        for name in self.shutdown:
            mask |= HardwareError[name.upper()]
        return int(mask)


class ServoConfig(StrictModel):
    """One servo: which channel it follows and its mechanical limits (servo degrees)."""

    id: int = Field(ge=0, le=252)
    model: str
    channel: str
    gain: float = 1.0
    zero_deg: float = 180.0
    direction: Literal[1, -1] = 1
    min_deg: float = 90.0
    max_deg: float = 270.0
    park_deg: float | None = None
    """Where parking leaves the servo; ``zero_deg`` when omitted."""
    max_speed_dps: float = Field(180.0, gt=0.0)
    max_accel_dps2: float = Field(2000.0, ge=0.0)
    """Profile Acceleration; 0 leaves acceleration unlimited."""

    @pydantic.field_validator("model", mode="before")
    @classmethod
    def _model_upper(cls, value: Any) -> Any:
        return value.upper() if isinstance(value, str) else value

    @property
    def spec(self) -> ModelSpec:
        return model_spec(self.model)

    @property
    def park(self) -> float:
        return self.zero_deg if self.park_deg is None else self.park_deg


class RigProblem(ValueError):
    """A rig map that parses but cannot be driven safely; ``key`` is the dotted path."""

    def __init__(self, key: str, message: str) -> None:
        self.key = key
        self.message = message
        super().__init__(f"{key}: {message}")


class RigConfig(StrictModel):
    """A whole rig: the bus and the servos (in the order the status lists them)."""

    name: str = Field(default="rig", pattern=NAME_PATTERN)
    """The rig's name: REST and the page arm it by this name (riderlive/names.py)."""
    description: str = ""
    bus: BusConfig = Field(default_factory=BusConfig)
    servos: dict[str, ServoConfig]

    @pydantic.model_validator(mode="after")
    def _check(self) -> RigConfig:
        for key, message in rig_problems(self):
            raise RigProblem(key, message)
        return self

    @property
    def ids(self) -> tuple[int, ...]:
        return tuple(s.id for s in self.servos.values())

    def with_port(self, port: str) -> RigConfig:
        """The same rig on another serial port (an emulator's pty, another adapter)."""
        return self.model_copy(update={"bus": self.bus.model_copy(update={"port": port})})


def rig_problems(rig: RigConfig) -> list[tuple[str, str]]:
    """Every reason ``rig`` cannot be driven safely, as (key, message) pairs."""
    problems: list[tuple[str, str]] = []
    bus = rig.bus
    if not rig.servos:
        problems.append(("servos", "a rig needs at least one servo"))
    if bus.baud not in SDK_BAUDS:
        problems.append(("bus.baud", f"{bus.baud} is not a baud rate the SDK can set; allowed: {SDK_BAUDS}"))
    if bus.bus_watchdog_ms % 20:
        problems.append(("bus.bus_watchdog_ms", f"{bus.bus_watchdog_ms} is not a multiple of 20 (the register's unit)"))
    min_watchdog = max(40.0, 3000.0 / bus.tick_hz)
    if 0 < bus.bus_watchdog_ms < min_watchdog:
        problems.append(("bus.bus_watchdog_ms", f"must be 0 (off) or >= {min_watchdog:.0f} (3 ticks, at least 40 ms)"))
    if bus.return_delay_us % 2:
        problems.append(("bus.return_delay_us", "must be even (the register's unit is 2 us)"))
    known_models = {m.value for m in Model}
    if rig.servos and bus.baud in SDK_BAUDS and all(s.model in known_models for s in rig.servos.values()):
        wire = wire_seconds_per_tick(rig)
        if wire > MAX_WIRE_SHARE * bus.tick_s:
            problems.append(
                (
                    "bus.tick_hz",
                    f"{len(rig.servos)} servos at {bus.baud} baud need {wire * 1000:.2f} ms of wire per tick "
                    f"(read every {bus.read_divider} ticks): at most {MAX_WIRE_SHARE / wire:.0f} ticks/s; "
                    "lower tick_hz, raise read_divider or the baud",
                )
            )
        read_tick = read_tick_seconds(rig)
        if read_tick > bus.tick_s:
            problems.append(
                (
                    "bus.tick_hz",
                    f"a tick with a read takes {read_tick * 1000:.2f} ms ({len(rig.servos)} servos at {bus.baud} "
                    f"baud, latency timer {bus.latency_timer_ms:g} ms): at most {1 / read_tick:.0f} ticks/s; "
                    "lower tick_hz or raise the baud",
                )
            )
    seen: dict[int, str] = {}
    for name, servo in rig.servos.items():
        key = f"servos.{name}"
        if servo.id in seen:
            problems.append((f"{key}.id", f"id {servo.id} is already used by servos.{seen[servo.id]}"))
        seen.setdefault(servo.id, name)
        if servo.model not in {m.value for m in Model}:
            known = ", ".join(m.value for m in Model)
            problems.append((f"{key}.model", f"unknown servo model {servo.model!r}; known: {known}"))
            continue
        if servo.channel not in RIDER_INDEX:
            problems.append((f"{key}.channel", f"unknown rider channel {servo.channel!r}; one of {RIDER_NAMES}"))
        spec = servo.spec
        if bus.baud in SDK_BAUDS and bus.baud not in spec.baud_rates.values():
            problems.append(("bus.baud", f"{servo.model} ({key}) cannot run at {bus.baud}"))
        span = f"the {servo.model}'s range is {MIN_DEG:g} .. {MAX_DEG:.2f} deg"
        for field in ("min_deg", "max_deg", "zero_deg", "park_deg"):
            value = getattr(servo, field)
            if value is not None and not MIN_DEG <= value <= MAX_DEG:
                problems.append((f"{key}.{field}", f"{value:g} is outside {span}"))
        if servo.min_deg >= servo.max_deg:
            problems.append((f"{key}.max_deg", f"must be above min_deg ({servo.min_deg:g})"))
        elif not servo.min_deg <= servo.park <= servo.max_deg:
            problems.append((f"{key}.park_deg", f"{servo.park:g} is outside [min_deg, max_deg]"))
        top_speed = spec.no_load_speed_rpm * 6.0
        if servo.max_speed_dps > top_speed:
            problems.append(
                (
                    f"{key}.max_speed_dps",
                    f"{servo.max_speed_dps:g} exceeds the {servo.model}'s no-load speed ({top_speed:.0f} deg/s)",
                )
            )
        if servo.gain == 0.0:
            problems.append((f"{key}.gain", "0 would never move the servo"))
    return problems


READ_BYTES = 15
"""The divided read: Present Position (132) .. Present Temperature (146)."""
MAX_WIRE_SHARE = 0.8
"""The share of a tick the bus may be busy: the rest absorbs USB latency and jitter."""


def wire_bytes_per_tick(servos: int, read_divider: int, fast: bool = True) -> float:
    """Protocol 2.0 bytes on the wire per tick: the goal SYNC_WRITE, plus 1/read_divider
    of a (Fast) Sync Read of ``READ_BYTES`` (request and replies; Return Delay Time 0)."""
    write = 14 + 5 * servos  # header 7, INST, address 2, length 2, CRC 2; then ID + 4 bytes each
    request = 14 + servos
    replies = 8 + (READ_BYTES + 4) * servos if fast else (11 + READ_BYTES) * servos
    return write + (request + replies) / read_divider


def _fast(rig: RigConfig) -> bool:
    return rig.bus.fast_sync_read and all(s.spec.fast_sync_read for s in rig.servos.values())


def wire_seconds_per_tick(rig: RigConfig) -> float:
    """Average wire time of one tick at the rig's baud (10 bits per byte)."""
    return wire_bytes_per_tick(len(rig.servos), rig.bus.read_divider, _fast(rig)) * 10.0 / rig.bus.baud


def read_tick_seconds(rig: RigConfig) -> float:
    """A tick with a read, start to end: the goal write and the whole read on the wire,
    plus the adapter's latency timer twice (the read's request and its reply)."""
    wire = wire_bytes_per_tick(len(rig.servos), 1, _fast(rig)) * 10.0 / rig.bus.baud
    return wire + 2.0 * rig.bus.latency_timer_ms / 1000.0


def longest_tick_wait_s(rig: RigConfig) -> float:
    """The longest one tick may legitimately block on this bus (s): a tick with a read
    whose reply never comes, waited for to the allowance's ceiling (``max_reply_wait_ms``,
    or ``timeout_margin_ms`` where that is larger) past the expected time. (The next tick
    drains the line for at most as long, but beats first.) The supervisor's hang detector
    adds it, so a tick waiting out one lost reply is not a hang."""
    allowance_ms = max(rig.bus.max_reply_wait_ms, rig.bus.timeout_margin_ms)
    return read_tick_seconds(rig) + (allowance_ms + 2.0 * rig.bus.latency_timer_ms) / 1000.0


def load_rig(path: str | Path) -> RigConfig:
    """Read and validate a rig map; a bare name is looked up in ``config/rigs``."""
    path = Path(path)
    if not path.suffix and not path.exists():
        path = RIG_DIR / f"{path}.toml"
    data = read_toml(path)
    return rig_from_dict(data, str(path))


def rig_from_dict(data: Any, source: str = "<rig>") -> RigConfig:
    """Validate an already-parsed rig map; errors name ``source`` and the key."""
    try:
        return RigConfig.model_validate(data)
    except pydantic.ValidationError as exc:
        for err in exc.errors():
            problem = err.get("ctx", {}).get("error")
            if isinstance(problem, RigProblem):
                raise ConfigError(source, problem.key, problem.message) from None
    return validate(RigConfig, data, source)  # raises with the field's own message


def wire_budget(rig: RigConfig) -> str:
    """Three lines on what the rig asks of its bus per tick (printed at start)."""
    bus = rig.bus
    wire = wire_seconds_per_tick(rig)
    return "\n".join(
        [
            f"{rig.name}: {len(rig.servos)} servos on {bus.port} at {bus.baud} baud, {bus.tick_hz:g} ticks/s, "
            f"read every {bus.read_divider} ticks",
            f"wire per tick {wire * 1000:.2f} ms = {wire * bus.tick_hz:.0%} of a tick "
            f"(at most {MAX_WIRE_SHARE:.0%}; the wire allows {1 / wire:.0f} ticks/s)",
            f"a tick with a read takes {read_tick_seconds(rig) * 1000:.2f} ms (at most one tick, "
            f"{bus.tick_s * 1000:.2f} ms)",
        ]
    )
