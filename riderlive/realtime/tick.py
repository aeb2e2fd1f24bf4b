"""The tick process: a fixed-rate loop that owns the rules and the devices.

It runs in its own process (``multiprocessing`` spawn) so no web traffic shares its
GIL. Each tick: wait for the deadline, apply pending commands, take new input frames
from the input ring, step :class:`~riderlive.realtime.core.TickCore`, tick the devices
(:class:`~riderlive.realtime.output.TickDevices`: the rig), write one record to the
output ring and wake the web process with one byte on the notify pipe (non-blocking: a
stalled web process cannot stall the tick). Status (driver, mode, e-stop, devices) goes
to a shared blob as JSON when it changes and at about 30 Hz while a device is there.

Between deadlines the tick sleeps on its command pipe (and a signal pipe): a command
wakes it at once, and an e-stop recorded in the latch is acted on at that moment (or
during the last millisecond's spin, or inside a bus wait), not at the next deadline.
Every tick it writes its heartbeat to the safety board, where the web process and the
guardian look for a dead or hung tick.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import time
from collections import deque
from multiprocessing.connection import Connection
from typing import TYPE_CHECKING, Any

from riderlive.channels import RIDER_PART_NAMES as PART_NAMES
from riderlive.devices import iowait
from riderlive.devices.board import SafetyBoard
from riderlive.devices.latch import StopLatch
from riderlive.horse import ProceduralHorse
from riderlive.realtime import handover, latency
from riderlive.realtime import layout as L
from riderlive.realtime.core import Driver, TickCore, TickResult
from riderlive.realtime.counters import COUNTERS, TickCounters
from riderlive.realtime.frame import frame_of
from riderlive.realtime.intake import Intake
from riderlive.realtime.output import TickDevices
from riderlive.realtime.pacing import DeadlineClock, bucket_of
from riderlive.realtime.phase_follow import PhaseFollower
from riderlive.realtime.record import LayoutMismatch, RecordLayout
from riderlive.realtime.setup import TickSetup
from riderlive.realtime.shm import SharedBlob, SharedCounters, SharedRing
from riderlive.realtime.tick_control import TickControl
from riderlive.rules.engine import RiderModel

if TYPE_CHECKING:
    from riderlive.realtime.tail import TickPhysics

log = logging.getLogger(__name__)
_PARTS_AT_REST = (0.0,) * len(PART_NAMES)
"""The rider parts of a frame that has none (the neutral stand-in before the first good step)."""


class TickLoop(TickControl):
    """The loop's state and the tick's steps; :meth:`run` returns when stopped. Commands, status
    and hand-over: :class:`~riderlive.realtime.tick_control.TickControl`."""

    def __init__(
        self,
        setup: TickSetup,
        commands: Connection,
        notify_fd: int,
        devices: TickDevices | None,
        *,
        latch: StopLatch | None = None,
        board: SafetyBoard | None = None,
    ) -> None:
        self.setup = setup
        self.commands = commands
        self.notify_fd = notify_fd
        self.devices = devices
        self._own_latch = latch is None
        self.latch = StopLatch() if latch is None else latch
        self.board = board
        self.wake_fds: list[int] = [commands.fileno()]
        names = setup.shm_names
        self.inputs = SharedRing(0, 0, name=names["input"])
        self.outputs = SharedRing(0, 0, name=names["output"])
        self.counters = SharedCounters(COUNTERS, name=names["counters"])
        self.counter = TickCounters(self.counters.values)
        """The counters by attribute (written by this process only)."""
        # No "histograms" name (a loop built without a TickLink): a block of its own, read by nobody.
        slots = latency.slot_names(latency.TICK_HISTOGRAMS)
        self.histogram_block = SharedCounters(slots, name=names.get("histograms"))
        self.histograms = latency.views(self.histogram_block.values, latency.TICK_HISTOGRAMS)
        self._snapshot_every = max(1, round(setup.rate / handover.SNAPSHOT_RATE))
        self._status_every = max(1, round(setup.rate / 30.0))
        self._last_driver = Driver.NEUTRAL
        """The driver of the last status (a change makes it dirty)."""
        self._unsent_rx = -1.0
        """Receive time of the newest input taken but not yet in a goal written to a device (or -1)."""
        self.phase = PhaseFollower(setup.rate, setup.phase_margin, setup.phase_lock)
        """The phase lock (started with the clock in :meth:`run`)."""
        self.status_blob = SharedBlob(name=names["status"])
        self.handover_blob = SharedBlob(name=names["handover"]) if "handover" in names else None
        """Where this tick writes its :class:`~riderlive.realtime.handover.TickSnapshot` (None: nobody takes over)."""
        self.settings = handover.Settings(setup.gait, setup.speed, setup.terrain, setup.mode)
        """As applied: the setup's, then the commands' (handed over)."""
        self.resume: handover.TickSnapshot | None = None
        """Set by a spare that takes over (``realtime/spare.py``): :meth:`run` goes on from it."""
        model = RiderModel(params=setup.params, scale=setup.length_scale, animator=setup.animator)
        ground = setup.terrain  # the procedural horse's ground, described in the status (None: flat)
        self.horse = ProceduralHorse(setup.gait, setup.speed, setup.seed, terrain=ground.terrain() if ground else None)
        self.terrain: dict[str, Any] | None = ground.describe() if ground else None
        self.core = TickCore(
            model, setup.timing, self.horse, setup.mode, setup.rider_bounds, saddle_point=setup.saddle_point
        )
        self.intake = Intake(self.inputs, self.core, self.counter, self.histograms["ingest_to_tick"], 1.0 / setup.rate)
        self._saddle_seen = (-1, -1)
        """Lock and gait codes of the last status (a change makes the status dirty)."""
        self._horse_seen: tuple[str, str | None] = ("", None)
        """The procedural horse's gait and move in the last status (a change makes it dirty: the page's header)."""
        self.running = True
        self.stopping_since: float | None = None
        self.realtime = "off"
        self.events: deque[str] = deque(maxlen=10)
        self.device_status: dict[str, Any] = {}
        self._status_dirty = True
        self._last_good: TickResult | None = None
        self._held = False
        """The last ``_step`` repeated the last good result (flagged in the tick's frame)."""
        self.physics: TickPhysics | None = None
        if setup.tail:
            from riderlive.realtime.tail import TickPhysics  # numba: imported only when on

            self.physics = TickPhysics(setup.physics_file, self.core.edges)
        self.layout = RecordLayout(self.physics.names if self.physics else (), PART_NAMES)
        """The output record as this tick packs it: the setup's, or the tick refuses to start."""
        setup.layout.require_same(self.layout, "the web process's setup", "the tick")
        if self.outputs.width != self.layout.width:
            raise LayoutMismatch(
                f"the output ring has {self.outputs.width} slots a record, the tick's layout {self.layout.describe()}"
            )

    def warm(self) -> None:
        """Compile or load the rider parts and physics kernels now, so compile time never lands in a tick."""
        self.core.parts.warm()
        if self.physics is not None:
            self.physics.warm(self.core.neutral_horse, self.core.neutral_rider)

    def _follow_phase(self, clock: DeadlineClock, now: float, arrivals: list[float]) -> None:
        """Step the phase lock with the driving producer's horse frames taken this tick; move the clock."""
        core = self.core
        driving = core.driver is Driver.INPUT and core.input_kind is L.InputKind.HORSE
        producer = core.producer if driving else -1
        self._status_dirty |= self.phase.follow(clock, now, producer, arrivals, self.counter)

    # -- the loop ---------------------------------------------------------------
    def run(self) -> None:
        """Tick until stopped, each tick in the documented order (``docs/architecture.md``):
        pace, e-stop and commands, read input, rules, devices, physics, pack and publish,
        counters."""
        clock = self._start_clock()
        self._publish_status()
        while self.running:
            woke = clock.wait_or_wake(self.wake_fds, None if self.devices is None else self.devices.stop_pending)
            if self.board is not None:
                iowait.beat(self.board, time.perf_counter())
            if woke is None:
                self._between_deadlines()
                continue
            deadline, lateness = woke
            now = deadline - self.setup.start
            self._stop_and_commands(deadline, now)
            newest_rx = self.intake.read(now, deadline, self.devices)
            result = self._rules(now)
            self._tick_devices(result, clock.tick, now, deadline, newest_rx)
            physics = self._step_physics(now, result)  # after the rig's transaction: the bus never waits on the tail
            done = self._pack_and_publish(
                clock.tick, now, result, newest_rx=newest_rx, lateness=lateness, physics=physics
            )
            self._after_output(clock, now, result)
            self._count_tick(clock, deadline, lateness, done)
            self._check_stopped(now)
        self.counter.alive = 0.0
        if self.devices is not None:
            self.device_status = self.devices.status()
        self._publish_status()

    def _start_clock(self) -> DeadlineClock:
        """Pace: the deadline grid (a spare's resumed one), the phase lock started on it."""
        setup = self.setup
        spin = setup.spin if setup.spin is not None else (0.00025 if self.realtime == "fifo" else 0.001)
        clock = DeadlineClock(period=1.0 / setup.rate, start=time.perf_counter(), spin=spin)
        self.phase.start(clock.start - setup.start)
        if self.resume is not None:
            self._resume_clock(clock, self.resume)
        self.counter.realtime = 1.0 if self.realtime == "fifo" else 0.0
        self.counter.alive = 1.0
        self._last_driver = self.core.driver
        return clock

    def _between_deadlines(self) -> None:
        """A command or a signal woke the loop before its deadline: e-stops first, then the commands."""
        if self.devices is not None:
            self.devices.act_on_stop(time.perf_counter())
        self._drain_wake_fds()
        self._poll_commands(time.perf_counter() - self.setup.start)

    def _stop_and_commands(self, deadline: float, now: float) -> None:
        """E-stop (a request in the latch acts on every device now), then the pending commands."""
        if self.devices is not None:
            self.devices.act_on_stop(deadline)
        self._poll_commands(now)

    def _rules(self, now: float) -> TickResult:
        """Step the rules (never raising, never non-finite); their faults and counters out."""
        result = self._step(now)
        core, counter = self.core, self.counter
        horse_now = (self.horse.gait, self.horse.move)
        if horse_now != self._horse_seen:
            self._horse_seen = horse_now
            self._status_dirty = True
        if core.faults:
            self.events.extend(core.faults)
            core.faults.clear()
            self._status_dirty = True
        counter.state_resets = core.resets
        counter.outputs_clamped = core.clamped
        self._count_saddle(result)
        self._count_rates(core.resampler.rate, core.saddle.clock.rate)
        counter.hands_full_reach = core.full_reach
        return result

    def _tick_devices(self, result: TickResult, tick: int, now: float, deadline: float, newest_rx: float) -> None:
        """Tick the devices with this tick's frame; the ingest-to-wire latency of a goal written."""
        devices = self.devices
        if devices is None:
            return
        changed = devices.tick(frame_of(result, tick, now, deadline, self.core.edges.metres_per_unit, self._held))
        self._unsent_rx = max(self._unsent_rx, newest_rx)
        if devices.goal_written_at is not None and self._unsent_rx >= 0.0:
            wire = devices.goal_written_at - self.setup.start - self._unsent_rx
            self.histograms["ingest_to_wire"].observe(wire)
            self._unsent_rx = -1.0
        if changed or tick % self._status_every == 0:
            self.device_status = devices.status()
            self._status_dirty = True

    def _step_physics(self, now: float, result: TickResult) -> list[float]:
        """The tail and braid at ``now`` (empty when off)."""
        physics = self.physics
        if physics is None:
            return []
        errors, fresh = physics.errors, physics.stepper is None
        values = physics.tick(now, result.horse, result.rider)
        if physics.errors != errors:
            self.events.append("the tail physics failed; restarted from rest")
        self._status_dirty |= fresh or physics.errors != errors
        self.counter.physics_errors = physics.errors
        self.counter.physics_skipped_steps = physics.skipped_steps
        return values

    def _pack_and_publish(
        self, tick: int, now: float, result: TickResult, *, newest_rx: float, lateness: float, physics: list[float]
    ) -> float:
        """One record into the output ring (packed by the layout), one byte to wake the web process; ``done``."""
        done = time.perf_counter() - self.setup.start
        record = self.layout.pack(
            seq=tick,
            engine_t=now,
            source_t=result.source_time,
            driver=result.driver,
            producer=result.producer,
            input_rx=newest_rx,
            done=done,
            lateness=lateness,
            saddle=result.saddle,
            estimate=result.estimate,
            horse=result.horse,
            rider=result.rider,
            physics=physics,
            parts=result.parts or _PARTS_AT_REST,
        )
        self.outputs.write(record)
        with contextlib.suppress(BlockingIOError, BrokenPipeError):
            os.write(self.notify_fd, b"\x01")
        return done

    def _after_output(self, clock: DeadlineClock, now: float, result: TickResult) -> None:
        """Off the latency path: the phase lock, the hand-over snapshot, the status."""
        if self.phase.enabled:
            self._follow_phase(clock, now, self.intake.arrivals)
        if self.handover_blob is not None and clock.tick % self._snapshot_every == 0:
            self._write_snapshot(clock, now)
        if result.driver is not self._last_driver:
            self._last_driver = result.driver
            self._status_dirty = True
        if self._status_dirty:
            self._publish_status()

    def _count_tick(self, clock: DeadlineClock, deadline: float, lateness: float, done: float) -> None:
        """The pacing counters and the lateness histogram."""
        step = done + self.setup.start - deadline
        self.counter.count_tick(clock.overruns, clock.skipped, lateness, step, bucket_of(lateness))
        self.histograms["tick_lateness"].observe(lateness)

    def _check_stopped(self, now: float) -> None:
        """A stop asked: done once the devices rest (or the park timeout passed)."""
        devices = self.devices
        if self.stopping_since is not None and (
            devices is None or devices.at_rest() or now - self.stopping_since > self.setup.park_timeout
        ):
            self.running = False

    def _count_saddle(self, result: TickResult) -> None:
        """The saddle estimator's counters into shared memory; a new lock or gait updates the status."""
        seen = (_code(result.estimate[0]), _code(result.estimate[1]))
        if seen != self._saddle_seen:
            self._saddle_seen = seen
            self._status_dirty = True
        if self.core.input_kind is L.InputKind.SADDLE:
            self.counter.set_saddle(self.core.saddle.counters())

    def _drain_wake_fds(self) -> None:
        for fd in self.wake_fds[1:]:  # the signal pipe (the command pipe is read by _poll_commands)
            with contextlib.suppress(BlockingIOError, OSError):
                os.read(fd, 4096)

    def _step(self, now: float) -> TickResult:
        """``core.step``, never raising and never returning a non-finite rider value.

        A failure or a NaN/inf (from a parameter change, say) repeats the last good
        frame, counted and reported: the rig must never be sent a non-finite goal.
        """
        self._held = False
        try:
            result = self.core.step(now)
            if all(math.isfinite(v) for v in result.rider):
                self._last_good = result
                return result
            self.counter.nonfinite_outputs += 1
            problem = "the rules produced a non-finite value"
        except Exception as exc:
            self.counter.step_errors += 1
            problem = f"tick step failed: {exc}"
        if not self.events or self.events[-1] != problem:
            self.events.append(problem)
            self._status_dirty = True
        self._held = True
        if self._last_good is None:
            neutral = self.core.neutral_rider
            self._last_good = TickResult(Driver.NEUTRAL, now, -1, list(self.core.neutral_horse), list(neutral))
        return self._last_good

    def close(self) -> None:
        if self.devices is not None:
            try:
                self.devices.close()
            except Exception as exc:
                log.warning("closing the devices failed: %s", exc)
        if self.board is not None and not self.running:
            self.board.tick_clean_exit = self.setup.generation
        self.histograms.clear()
        for shared in (self.inputs, self.outputs, self.counters, self.histogram_block, self.status_blob):
            shared.close()
        if self.handover_blob is not None:
            self.handover_blob.close()
        if self._own_latch:
            self.latch.close()


def _code(value: float) -> int:
    """A lock or gait code of a record (-1: none)."""
    return -1 if math.isnan(value) else int(value)
