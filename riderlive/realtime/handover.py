"""The tick's state handed from a dead or hung generation to the warm spare that takes over.

The running tick writes one :class:`TickSnapshot` to shared memory after every tick's
output is out (never on the latency path; ~20 us, docs/performance.md); the spare reads
the newest complete one at takeover (``realtime/spare.py``) and goes on from there:

- **what is copied**: the :class:`~riderlive.realtime.core.TickCore` state that is not
  rebuilt from the setup (:class:`CoreState`: driver and since when, producer and input
  kind, producers gone, the driver and parameter blends, the smoothing and follow-through
  filters, the last rider), the procedural horse (its pure state: gait, speed, moves,
  terrain), the phase lock's state, the deadline grid (its origin and tick index, so the
  records' ``seq`` and the locked phase continue), the overrun counts, the recent events;
- **what is replayed**: the input stream. The resampler's buffer (or the saddle
  estimator) is a function of the records pushed since the producer's stream began, and
  those are still in the input ring: the spare pushes the last :data:`REPLAY` records
  before the dead tick's read position through the same ``TickCore.push_input`` and
  then reads on from that position (no frame is lost or taken twice);
- **what is rebuilt**: the settings (the rules' parameters, the animator layer, mode,
  gait, terrain) come from the setup the web process hands the spare
  (``TickLink.apply``), the rider parts and physics from their files;
- **the tail physics** (``realtime/tail.py``, :class:`~riderlive.realtime.tail.TailState`):
  the strands' state, the stepper's clock and the tick frames it interpolates between; the
  new generation steps on from them across the gap (at most ``MAX_CATCH_UP`` steps), so
  the tail goes on moving instead of restarting from rest;
- **what is not handed over**: the devices (the guardian parked what was armed; the new
  generation connects them disarmed).

At the first tick after the takeover the rider blends from the last frame the dead tick
published to the new output over :data:`BLEND_S` (a smoothstep): the rider goes on
without a jump larger than one tick's motion, however long the gap was.

A snapshot is versioned (:data:`VERSION`): a spare from another build ignores it and
starts fresh (counted, logged). Pickled: both ends are this package, in this install.
"""

from __future__ import annotations

import dataclasses
import pickle
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from riderlive.realtime import layout as L
from riderlive.realtime import phase_lock as phase
from riderlive.realtime.core import Driver, Mode
from riderlive.rules.animator import DamperState, SpringState

if TYPE_CHECKING:
    from riderlive.horse import ProceduralHorse, TerrainConfig
    from riderlive.realtime.core import TickCore
    from riderlive.realtime.shm import SharedRing
    from riderlive.realtime.tail import TailState, TickPhysics

VERSION = 2
"""Bumped whenever a field of :class:`TickSnapshot` or :class:`CoreState` changes."""
REPLAY = 512
"""Input records replayed at takeover: the resampler's capacity (``Resampler.capacity``)."""
SNAPSHOT_BYTES = 1 << 18
"""Size of the shared blob (a snapshot pickles to a few KiB)."""
BLEND_S = 0.2
"""Seconds over which the first frames after a takeover blend from the last published one
(``Timing.blend_time`` when shorter): a smoothstep, so the first step is a small part of
the difference, whatever the gap."""
SNAPSHOT_RATE = 60.0
"""Snapshots written per second, about (every tick up to this rate): the input is replayed
and the blend starts from the last published frame, so an older snapshot costs little."""


@dataclass(frozen=True)
class CoreState:
    """The part of :class:`TickCore`'s state that is neither rebuilt from the setup nor replayed."""

    mode: Mode
    driver: Driver
    driver_since: float
    producer: int
    input_kind: L.InputKind
    gone: tuple[int, ...]
    blend_from: list[float] | None
    blend_start: float
    blend_duration: float
    damper: DamperState | None
    spring: SpringState | None
    last_now: float | None
    last_rider: list[float] | None
    param_delta: list[float] | None
    param_start: float
    clamped: int
    resets: int
    full_reach: int


CORE_FIELDS = {
    "mode": "mode",
    "driver": "driver",
    "driver_since": "driver_since",
    "producer": "producer",
    "input_kind": "input_kind",
    "gone": "_gone",
    "blend_from": "_blend_from",
    "blend_start": "_blend_start",
    "blend_duration": "_blend_duration",
    "damper": "_damper",
    "spring": "_spring",
    "last_now": "_last_now",
    "last_rider": "last_rider",
    "param_delta": "_param_delta",
    "param_start": "_param_start",
    "clamped": "clamped",
    "resets": "resets",
    "full_reach": "full_reach",
}
""":class:`CoreState` field -> the ``TickCore`` attribute it holds."""
CORE_REBUILT = frozenset(
    {
        "timing", "horse", "resampler", "saddle_point", "saddle", "model", "_previous_model", "neutral_horse",
        "neutral_rider", "edges", "parts", "low", "high", "_last_reset", "faults",
        "_no_parts",
    }
)  # fmt: skip
"""``TickCore`` attributes rebuilt from the setup, replayed from the ring, or transient (a test
checks that every attribute is in one of the two sets: a new one must be placed)."""


@dataclass(frozen=True)
class Settings:
    """The horse and source settings a tick has applied (its setup's, then its commands')."""

    gait: str
    speed: float | None
    terrain: TerrainConfig | None
    mode: Mode


@dataclass(frozen=True)
class TickSnapshot:
    """What one tick generation hands the next (see the module docstring). Times: engine
    seconds, except ``clock_start`` (``perf_counter`` seconds, shared by the processes)."""

    version: int
    generation: int
    tick: int
    """Index of the deadline of the last tick (the output records' ``seq``)."""
    clock_start: float
    """The deadline grid's origin (moved by the phase lock)."""
    now: float
    """Engine time of the last tick."""
    overruns: int
    skipped: int
    input_next: int
    """The input ring's read position after the last tick."""
    core: CoreState
    horse: ProceduralHorse
    phase: phase.State
    events: tuple[str, ...]
    settings: Settings
    """As applied by the dead tick: a setting changed while no tick ran wins over its state."""
    tail: TailState | None = None
    """The tail physics' state (None: no physics, or before its first tick)."""


def capture_core(core: TickCore) -> CoreState:
    values: dict[str, Any] = {name: getattr(core, attribute) for name, attribute in CORE_FIELDS.items()}
    values["gone"] = tuple(sorted(values["gone"]))[-64:]
    return CoreState(**values)


def restore_core(core: TickCore, state: CoreState) -> None:
    for name, attribute in CORE_FIELDS.items():
        value = getattr(state, name)
        setattr(core, attribute, set(value) if name == "gone" else value)


def encode(snapshot: TickSnapshot) -> bytes:
    return pickle.dumps(snapshot, protocol=pickle.HIGHEST_PROTOCOL)


def decode(data: bytes | None) -> TickSnapshot | None:
    """The snapshot in ``data``; None when there is none or it is from another version."""
    if not data:
        return None
    try:
        snapshot = pickle.loads(data)
    except Exception:  # another build's classes: start fresh
        return None
    if not isinstance(snapshot, TickSnapshot) or snapshot.version != VERSION:
        return None
    for part, kind in ((snapshot, TickSnapshot), (snapshot.core, CoreState)):  # an install upgraded in place
        if not all(hasattr(part, f.name) for f in dataclasses.fields(kind)):
            return None
    return snapshot


def restore_tail(physics: TickPhysics | None, snapshot: TickSnapshot) -> bool:
    """The tail physics goes on from the snapshot's strands (False: none to hand, or it does
    not fit this generation's physics: the strands start from rest at its first tick)."""
    return physics is not None and snapshot.tail is not None and physics.restore(snapshot.tail)


def replay_inputs(core: TickCore, ring: SharedRing, until: int) -> int:
    """Push the last :data:`REPLAY` input records before ``until`` into ``core`` (a fresh
    core whose ``gone`` set is restored); the records replayed."""
    first = max(0, until - REPLAY, ring.head - (ring.capacity - 1))
    replayed = 0
    for k in range(first, until):
        record = ring.read(k)
        if record is None:
            continue
        core.push_record(L.InputRecord.of(record))
        replayed += 1
    return replayed


def restore(
    core: TickCore,
    ring: SharedRing,
    snapshot: TickSnapshot,
    now: float,
    blend_time: float,
    *,
    settings: Settings | None = None,
) -> int:
    """Hand ``snapshot`` to a fresh ``core``: the gone producers, the input replayed, the rest
    copied, and a blend from the last published rider starting at engine time ``now``.
    ``settings``: as the new generation was started with; where they differ from the
    snapshot's (changed while no tick ran) they win: the core's mode, and the procedural
    horse as built fresh from them instead of the dead tick's. Returns the records
    replayed; the ring's read position is set to go on after them."""
    core._gone = set(snapshot.core.gone)
    replayed = replay_inputs(core, ring, snapshot.input_next)
    ring.read_next = snapshot.input_next
    restore_core(core, snapshot.core)
    settings = settings or snapshot.settings
    if settings.mode is not snapshot.settings.mode:
        core.mode = settings.mode
    ours, theirs = snapshot.settings, settings
    if (ours.gait, ours.speed, ours.terrain) == (theirs.gait, theirs.speed, theirs.terrain):
        core.horse = snapshot.horse
    if snapshot.core.last_rider is not None and blend_time > 0.0:
        core._blend_from = list(snapshot.core.last_rider)
        core._blend_start = now
        core._blend_duration = blend_time
    return replayed
