"""The tick loop's edges to the web process: commands in, status and hand-over snapshots out.

:class:`TickControl` is the part of :class:`~riderlive.realtime.tick.TickLoop` that is not
the tick's own steps: it applies the commands from the command pipe (settings, operators'
requests to the devices, stop), builds the status written to the shared status blob, and
writes and resumes from the :class:`~riderlive.realtime.handover.TickSnapshot` a warm spare
takes over from. Every method runs in the tick's thread; the attributes it uses are the
loop's (declared below, set by ``TickLoop.__init__``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import time
from collections import deque
from multiprocessing.connection import Connection
from typing import Any

import orjson

from riderlive.devices.latch import StopLatch
from riderlive.horse import ProceduralHorse, TerrainConfig
from riderlive.realtime import commands as cmd
from riderlive.realtime import handover
from riderlive.realtime import layout as L
from riderlive.realtime.core import Driver, TickCore
from riderlive.realtime.counters import TickCounters
from riderlive.realtime.output import TickDevices
from riderlive.realtime.pacing import DeadlineClock
from riderlive.realtime.phase_follow import PhaseFollower
from riderlive.realtime.record import RecordLayout
from riderlive.realtime.setup import TickSetup
from riderlive.realtime.shm import SharedBlob, SharedRing
from riderlive.rules.engine import RiderModel
from riderlive.saddle import estimate as saddle_estimate

RATE_SHOWN = 0.001
"""A producer clock rate the status shows is refreshed once the rate in use moved more than this."""


class TickControl:
    """Commands, status and hand-over of a tick loop (a base of ``TickLoop``)."""

    setup: TickSetup
    commands: Connection
    devices: TickDevices | None
    latch: StopLatch
    core: TickCore
    horse: ProceduralHorse
    terrain: dict[str, Any] | None
    settings: handover.Settings
    events: deque[str]
    device_status: dict[str, Any]
    stopping_since: float | None
    realtime: str
    phase: PhaseFollower
    physics: Any
    status_blob: SharedBlob
    handover_blob: SharedBlob | None
    inputs: SharedRing
    outputs: SharedRing
    resume: handover.TickSnapshot | None
    _status_dirty: bool
    counter: TickCounters
    _rates_seen: tuple[float, float] = (0.0, 0.0)
    """The horse and saddle clock rates the status last showed."""

    def _count_rates(self, horse: float, saddle: float) -> None:
        """The producer clock rates in use (``resample.ClockMap.rate``) into shared memory; one
        that moved more than :data:`RATE_SHOWN` since the status showed it (at most 4 estimates
        a second per stream) refreshes the status (``input_clock_rate``, ``saddle_clock_rate``)."""
        self.counter.input_clock_rate = horse
        self.counter.saddle_clock_rate = saddle
        shown_horse, shown_saddle = self._rates_seen
        if abs(horse - shown_horse) > RATE_SHOWN or abs(saddle - shown_saddle) > RATE_SHOWN:
            self._rates_seen = (horse, saddle)
            self._status_dirty = True

    def _publish_status(self) -> None:
        """The status into the shared blob (the web process reads it when its version moves)."""
        self.status_blob.write(orjson.dumps(self.status()))
        self._status_dirty = False

    # -- commands ---------------------------------------------------------------
    def _handle(self, command: cmd.Command, now: float) -> None:
        if isinstance(command, cmd.SetMode):
            self.core.set_mode(command.mode, now)
            self.settings = dataclasses.replace(self.settings, mode=command.mode)
        elif isinstance(command, cmd.SetGait):
            self.horse.set_gait(command.gait, command.speed)
            self.settings = dataclasses.replace(self.settings, gait=command.gait, speed=command.speed)
        elif isinstance(command, cmd.SetTerrain):
            ground = command.terrain or TerrainConfig(slope=0.0)
            self.terrain = ground.describe(self.horse.set_terrain(ground.terrain()))
            self.settings = dataclasses.replace(self.settings, terrain=command.terrain)
        elif isinstance(command, cmd.Perform):
            self.horse.perform(command.move)  # an unknown move: ValueError, an event (_poll_commands)
        elif isinstance(command, cmd.SetModel):
            model = RiderModel(params=command.params, scale=self.setup.length_scale, animator=command.animator)
            self.core.set_model(model)
        elif isinstance(command, cmd.ProducerGone):
            self.core.producer_gone(command.producer)
        elif isinstance(command, cmd.EStop):
            if self.devices is not None:
                self.devices.act_on_stop(time.perf_counter())
        elif isinstance(command, cmd.Arm | cmd.Disarm | cmd.Reset | cmd.Reload | cmd.Tune):
            self._request(command)
            return  # its status is written already, before the reply
        elif isinstance(command, cmd.Stop):
            self._begin_stop(now)
        self._status_dirty = True

    def _request(self, command: cmd.Request) -> None:
        """An operator's request: applied by the devices, answered on the command pipe after the
        status blob says what the reply says (a ``GET /api/devices`` right after a ``200`` to
        ``POST /api/arm`` read ``disarmed`` for up to a tick: the bench's retry then armed twice)."""
        if self.devices is not None:
            reply = self.devices.request(command)
            self.device_status = self.devices.status()
        elif isinstance(command, cmd.Reset):
            self.latch.clear()
            reply = cmd.Reply(command.request, True, {}, None, "reset: no devices")
        else:
            reply = cmd.Reply(command.request, False, {}, "unknown_device", "no devices are configured")
        self._publish_status()
        if command.request:
            with contextlib.suppress(OSError, ValueError):
                self.commands.send(reply)

    def _begin_stop(self, now: float) -> None:
        if self.stopping_since is None:
            self.stopping_since = now
            if self.devices is not None:
                self.devices.park()

    def _poll_commands(self, now: float) -> None:
        try:
            while self.commands.poll():
                self._handle(self.commands.recv(), now)
        except (EOFError, OSError):  # the web process is gone: park and stop
            self._begin_stop(now)
        except Exception as exc:  # a bad command must not stop the tick
            self.events.append(f"command failed: {exc}")
            self._status_dirty = True

    # -- status -----------------------------------------------------------------
    def status(self) -> dict[str, Any]:
        core = self.core
        return {
            "driver": core.driver.name.lower(),
            "mode": core.mode.value,
            "producer": core.producer,
            "gait": self.horse.gait,
            "move": self.horse.move,
            "speed": self.horse.speed,
            "terrain": self.terrain,
            "estop": self.latch.latched,
            "realtime": self.realtime,
            "rate": self.setup.rate,
            "generation": self.setup.generation,
            "preset": core.model.params.name,
            "stopping": self.stopping_since is not None,
            "rig": None,
            "platform": None,
            "devices": [],
            **self.device_status,
            "physics": None if self.physics is None else self.physics.status(),
            "saddle": self._saddle_status(),
            "phase_lock": self.phase.status(),
            "input_clock_rate": core.resampler.rate,
            "saddle_clock_rate": core.saddle.clock.rate,
            "events": list(self.events),
        }

    def _saddle_status(self) -> dict[str, Any] | None:
        """The saddle estimate while a saddle input drives (docs/saddle.md), else None."""
        core = self.core
        if core.driver is not Driver.INPUT or core.input_kind is not L.InputKind.SADDLE:
            return None
        source_t = core.saddle.source_time(time.perf_counter() - self.setup.start)
        return saddle_estimate(core.saddle.state, source_t).as_dict()

    def _resume_clock(self, clock: DeadlineClock, snapshot: handover.TickSnapshot) -> None:
        """Go on on the dead generation's deadline grid: the same origin (and locked phase), the
        ``seq`` counting on; the deadlines of the gap are passed over, not counted as skipped."""
        clock.start = snapshot.clock_start
        clock.overruns, clock.skipped = snapshot.overruns, snapshot.skipped
        clock.tick = max(snapshot.tick, int((time.perf_counter() - clock.start) / clock.period))
        if self.phase.enabled:
            self.phase.state = snapshot.phase

    def _write_snapshot(self, clock: DeadlineClock, now: float) -> None:
        """The state a spare needs to take over (``realtime/handover.py``), into shared memory."""
        assert self.handover_blob is not None
        snapshot = handover.TickSnapshot(
            handover.VERSION,
            self.setup.generation,
            clock.tick,
            clock.start,
            now,
            clock.overruns,
            clock.skipped,
            self.inputs.read_next,
            handover.capture_core(self.core),
            self.horse,
            self.phase.state,
            tuple(self.events),
            self.settings,
            None if self.physics is None else self.physics.capture(),
        )
        self.handover_blob.write(handover.encode(snapshot))

    def take_over(self, snapshot: handover.TickSnapshot | None) -> int:
        """Before :meth:`run`, in a spare taking over: go on from ``snapshot`` (None: start
        fresh, reading the input ring from where the web process's records are now). Blends
        from the last rider the web process published. Returns the input records replayed."""
        if snapshot is None:
            self.inputs.read_next = self.inputs.head
            return 0
        self.resume = snapshot
        now = time.perf_counter() - self.setup.start
        blend = min(self.setup.timing.blend_time, handover.BLEND_S)
        replayed = handover.restore(self.core, self.inputs, snapshot, now, blend, settings=self.settings)
        self.horse = self.core.horse
        last = self.outputs.latest()
        if last is not None and self.core.last_rider is not None:
            rider = RecordLayout.rider.of(last).tolist()
            if len(rider) == len(self.core.last_rider) and all(math.isfinite(v) for v in rider):
                self.core._blend_from = rider  # the last frame anyone saw, newer than the snapshot
        self.events.extend(snapshot.events)
        self.events.append(f"took over from generation {snapshot.generation} ({replayed} input records replayed)")
        return replayed
