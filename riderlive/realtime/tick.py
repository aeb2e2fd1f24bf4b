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
import dataclasses
import gc
import logging
import math
import os
import signal
import threading
import time
from collections import deque
from multiprocessing.connection import Connection
from typing import TYPE_CHECKING, Any

import orjson

from riderlive.channels import RIDER_PART_NAMES as PART_NAMES
from riderlive.devices.board import SafetyBoard
from riderlive.devices.latch import StopLatch, StopSource
from riderlive.horse import ProceduralHorse, TerrainConfig
from riderlive.realtime import commands as cmd
from riderlive.realtime import handover, latency
from riderlive.realtime import layout as L
from riderlive.realtime.core import Driver, TickCore, TickResult, frame_of
from riderlive.realtime.output import TickDevices
from riderlive.realtime.pacing import DeadlineClock, bucket_of, try_realtime_priority
from riderlive.realtime.phase_follow import PhaseFollower
from riderlive.realtime.setup import TickSetup
from riderlive.realtime.shm import SharedBlob, SharedCounters, SharedRing
from riderlive.rules.engine import RiderModel
from riderlive.saddle import estimate as saddle_estimate
from riderlive.units import metres_per_unit

if TYPE_CHECKING:
    from riderlive.realtime.tail import TickPhysics

log = logging.getLogger(__name__)
_PARTS_AT_REST = (0.0,) * len(PART_NAMES)
"""The rider parts of a frame that has none (the neutral stand-in before the first good step)."""


class TickLoop:
    """The loop's state; :meth:`run` returns when stopped."""

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
        self.counters = SharedCounters(L.COUNTERS, name=names["counters"])
        # No "histograms" name (a loop built without a TickLink): a block of its own, read by nobody.
        slots = latency.slot_names(latency.TICK_HISTOGRAMS)
        self.histogram_block = SharedCounters(slots, name=names.get("histograms"))
        self.histograms = latency.views(self.histogram_block.values, latency.TICK_HISTOGRAMS)
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
        self.terrain = ground.describe() if ground else None
        self.core = TickCore(
            model, setup.timing, self.horse, setup.mode, setup.rider_bounds, saddle_point=setup.saddle_point
        )
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
        self.metres_per_unit = metres_per_unit(setup.length_scale)
        self.physics: TickPhysics | None = None
        if setup.tail:
            from riderlive.realtime.tail import TickPhysics  # numba: imported only when on

            self.physics = TickPhysics(setup.physics_file, setup.length_scale)
        if (*(self.physics.names if self.physics else ()), *PART_NAMES) != setup.extra_channels:
            raise ValueError("the tick's extra channels (physics, rider parts) differ from the web process's")

    def warm(self) -> None:
        """Compile or load the rider parts and physics kernels now, so compile time never lands in a tick."""
        self.core.parts.warm()
        if self.physics is not None:
            self.physics.warm(self.core.neutral_horse, self.core.neutral_rider)

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
            perform = getattr(self.horse, "perform", None)
            if perform is None:
                self.events.append(f"this procedural horse cannot perform {command.move!r}")
            else:
                perform(command.move)
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
        elif isinstance(command, cmd.Stop):
            self._begin_stop(now)
        self._status_dirty = True

    def _request(self, command: cmd.Request) -> None:
        """An operator's request: applied by the devices, answered on the command pipe."""
        if self.devices is not None:
            reply = self.devices.request(command)
        elif isinstance(command, cmd.Reset):
            self.latch.clear()
            reply = cmd.Reply(command.request, True, {}, None, "reset: no devices")
        else:
            reply = cmd.Reply(command.request, False, {}, "unknown_device", "no devices are configured")
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
            "move": getattr(self.horse, "move", None),
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
            "events": list(self.events),
        }

    def _saddle_status(self) -> dict[str, Any] | None:
        """The saddle estimate while a saddle input drives (docs/saddle.md), else None."""
        core = self.core
        if core.driver is not Driver.INPUT or core.input_kind is not L.InputKind.SADDLE:
            return None
        source_t = core.saddle.source_time(time.perf_counter() - self.setup.start)
        return saddle_estimate(core.saddle.state, source_t).as_dict()

    def _follow_phase(self, clock: DeadlineClock, now: float, arrivals: list[float], values: Any) -> None:
        """Step the phase lock with the driving producer's horse frames taken this tick; move the clock."""
        core = self.core
        driving = core.driver is Driver.INPUT and core.input_kind is L.InputKind.HORSE
        producer = core.producer if driving else -1
        self._status_dirty |= self.phase.follow(
            clock, now, producer, arrivals, values=values, index=self.counters.index
        )

    def _publish_status(self) -> None:
        self.status_blob.write(orjson.dumps(self.status()))
        self._status_dirty = False

    # -- the loop ---------------------------------------------------------------
    def run(self) -> None:
        setup = self.setup
        values = self.counters.values
        index = self.counters.index
        bucket0 = index["lateness_bucket_0"]
        spin = setup.spin if setup.spin is not None else (0.00025 if self.realtime == "fifo" else 0.001)
        clock = DeadlineClock(period=1.0 / setup.rate, start=time.perf_counter(), spin=spin)
        self.phase.start(clock.start - setup.start)
        if self.resume is not None:
            self._resume_clock(clock, self.resume)
        snapshot_every = max(1, round(setup.rate / handover.SNAPSHOT_RATE))
        arrivals: list[float] = []
        status_every = max(1, round(setup.rate / 30.0))
        values[index["realtime"]] = 1.0 if self.realtime == "fifo" else 0.0
        values[index["alive"]] = 1.0
        last_driver = self.core.driver
        devices = self.devices
        self._publish_status()
        while self.running:
            woke = clock.wait_or_wake(self.wake_fds, None if devices is None else devices.stop_pending)
            if self.board is not None:
                self.board["tick_beat"] = time.perf_counter()
            if woke is None:  # a command or a signal between deadlines: e-stops first
                if devices is not None:
                    devices.act_on_stop(time.perf_counter())
                self._drain_wake_fds()
                self._poll_commands(time.perf_counter() - setup.start)
                continue
            deadline, lateness = woke
            now = deadline - setup.start
            if devices is not None:
                devices.act_on_stop(deadline)
            self._poll_commands(now)
            newest_rx = -1.0
            arrivals.clear()
            for record in self.inputs.read_new():
                values_list = record[L.IN_VALUES :].tolist()
                rx = float(record[L.IN_RECEIVED])
                kind = L.InputKind(int(record[L.IN_KIND]))
                producer = int(record[L.IN_PRODUCER])
                switched = producer != self.core.producer
                if self.core.push_input(producer, float(record[L.IN_T]), rx, values_list, kind):
                    values[index["input_frames"]] += 1
                    if switched:  # only the new driver's frames count for the phase lock
                        arrivals.clear()
                    if kind is L.InputKind.HORSE:
                        arrivals.append(rx)
                else:
                    values[index["input_out_of_order"]] += 1
                newest_rx = max(newest_rx, rx)
            values[index["input_lapped"]] = self.inputs.lapped
            if newest_rx >= 0.0:
                self.histograms["ingest_to_tick"].observe(now - newest_rx)
            result = self._step(now, values, index)
            horse_now = (self.horse.gait, self.horse.move)
            if horse_now != self._horse_seen:
                self._horse_seen = horse_now
                self._status_dirty = True
            if self.core.faults:
                self.events.extend(self.core.faults)
                self.core.faults.clear()
                self._status_dirty = True
            values[index["state_resets"]] = self.core.resets
            values[index["outputs_clamped"]] = self.core.clamped
            self._count_saddle(result, values, index)
            values[index["hands_full_reach"]] = self.core.full_reach
            if devices is not None:
                changed = devices.tick(frame_of(result, clock.tick, now, deadline, self.metres_per_unit, self._held))
                self._unsent_rx = max(self._unsent_rx, newest_rx)
                if devices.goal_written_at is not None and self._unsent_rx >= 0.0:
                    wire = devices.goal_written_at - setup.start - self._unsent_rx
                    self.histograms["ingest_to_wire"].observe(wire)
                    self._unsent_rx = -1.0
                if changed or clock.tick % status_every == 0:
                    self.device_status = devices.status()
                    self._status_dirty = True
            extra: list[float] = []  # after the rig's transaction: the bus never waits on the tail
            if self.physics is not None:
                errors, fresh = self.physics.errors, self.physics.stepper is None
                extra = self.physics.tick(now, result.horse, result.rider)
                if self.physics.errors != errors:
                    self.events.append("the tail physics failed; restarted from rest")
                self._status_dirty |= fresh or self.physics.errors != errors
                values[index["physics_errors"]] = self.physics.errors
                values[index["physics_skipped_steps"]] = self.physics.skipped_steps
            done = time.perf_counter() - setup.start
            record_out = [
                float(clock.tick),
                now,
                result.source_time,
                float(result.driver),
                float(result.producer),
                newest_rx,
                done,
                lateness,
                *result.saddle,
                *result.estimate,
                *result.horse,
                *result.rider,
                *extra,
                *(result.parts or _PARTS_AT_REST),
            ]
            self.outputs.write(record_out)
            with contextlib.suppress(BlockingIOError, BrokenPipeError):
                os.write(self.notify_fd, b"\x01")
            if self.phase.enabled:  # after the output is out: never on the latency path
                self._follow_phase(clock, now, arrivals, values)
            if self.handover_blob is not None and clock.tick % snapshot_every == 0:
                self._write_snapshot(clock, now)
            if result.driver is not last_driver:
                last_driver = result.driver
                self._status_dirty = True
            if self._status_dirty:
                self._publish_status()
            values[index["ticks"]] += 1
            values[index["overruns"]] = clock.overruns
            values[index["skipped"]] = clock.skipped
            values[index["lateness_sum"]] += lateness
            values[index["lateness_max"]] = max(values[index["lateness_max"]], lateness)
            values[index["step_max"]] = max(values[index["step_max"]], done + setup.start - deadline)
            values[bucket0 + bucket_of(lateness)] += 1
            self.histograms["tick_lateness"].observe(lateness)
            if self.stopping_since is not None and (
                devices is None or devices.at_rest() or now - self.stopping_since > setup.park_timeout
            ):
                self.running = False
        values[index["alive"]] = 0.0
        if devices is not None:
            self.device_status = devices.status()
        self._publish_status()

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
            rider = last[L.OUT_RIDER : L.OUTPUT_WIDTH].tolist()
            if len(rider) == len(self.core.last_rider) and all(math.isfinite(v) for v in rider):
                self.core._blend_from = rider  # the last frame anyone saw, newer than the snapshot
        self.events.extend(snapshot.events)
        self.events.append(f"took over from generation {snapshot.generation} ({replayed} input records replayed)")
        return replayed

    def _count_saddle(self, result: TickResult, values: Any, index: dict[str, int]) -> None:
        """The saddle estimator's counters into shared memory; a new lock or gait updates the status."""
        seen = (_code(result.estimate[0]), _code(result.estimate[1]))
        if seen != self._saddle_seen:
            self._saddle_seen = seen
            self._status_dirty = True
        if self.core.input_kind is L.InputKind.SADDLE:
            for name, count in self.core.saddle.counters().items():
                values[index[f"saddle_{name}"]] = count

    def _drain_wake_fds(self) -> None:
        for fd in self.wake_fds[1:]:  # the signal pipe (the command pipe is read by _poll_commands)
            with contextlib.suppress(BlockingIOError, OSError):
                os.read(fd, 4096)

    def _step(self, now: float, values: Any, index: dict[str, int]) -> TickResult:
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
            values[index["nonfinite_outputs"]] += 1
            problem = "the rules produced a non-finite value"
        except Exception as exc:
            values[index["step_errors"]] += 1
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
            self.board["tick_clean_exit"] = float(self.setup.generation)
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


def tick_main(setup: TickSetup, commands: Connection, notify: Connection) -> None:
    """Entry point of the spawned tick process (a cold start: the first generation, or one
    with no warm spare ready)."""
    serve(prepare(setup, commands, notify.fileno()))


def prepare(setup: TickSetup, commands: Connection, notify_fd: int) -> TickLoop:
    """The loop, attached to the shared memory, without devices and not warmed yet."""
    os.set_blocking(notify_fd, False)
    latch = StopLatch(setup.latch_name) if setup.latch_name else StopLatch()
    board = SafetyBoard(setup.board_name) if setup.board_name else None
    return TickLoop(setup, commands, notify_fd, None, latch=latch, board=board)


def discard(loop: TickLoop) -> None:
    """Detach a loop that never ran (a spare's warm-up loop replaced at takeover)."""
    loop.close()
    loop.latch.close()
    if loop.board is not None:
        loop.board.close()


def serve(loop: TickLoop, warmed: bool = False) -> None:
    """Connect the devices (disarmed; armed once with ``serve --arm`` in the first generation
    only), warm the kernels unless ``warmed``, and run until stopped; then detach."""
    setup = loop.setup
    in_process = threading.current_thread() is threading.main_thread()
    if in_process:
        logging.basicConfig(level=logging.INFO, format="%(levelname)s tick: %(message)s")
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # the web process decides when to stop
    latch, board = loop.latch, loop.board
    devices: TickDevices | None = None
    if setup.devices:
        arm = setup.arm_on_start if setup.generation == 1 else None
        devices = loop.devices = TickDevices(setup.devices, latch, board, setup.guardian, arm)
        for name, changes in setup.tunes.items():  # live parameters applied before this generation
            reply = devices.request(cmd.Tune(name, changes, "restart"))
            if not reply.ok:
                loop.events.append(f"{name}: the live parameters kept from before were refused: {reply.message}")
    if in_process:
        wake_read, wake_write = os.pipe()
        os.set_blocking(wake_read, False)
        os.set_blocking(wake_write, False)
        signal.set_wakeup_fd(wake_write, warn_on_full_buffer=False)
        loop.wake_fds.append(wake_read)

        def on_term(signum: int, frame: object) -> None:  # SIGTERM of the driving process: e-stop
            latch.request(StopSource.SIGNAL)
            loop._begin_stop(time.perf_counter() - setup.start)

        signal.signal(signal.SIGTERM, on_term)
    try:
        # The parts and physics kernels compile (cold cache) or load here: before real-time priority
        # (a 10-20 s compile at FIFO would starve the web process), before the collector is
        # frozen (compiling makes cyclic garbage) and before the first deadline.
        if not warmed:
            loop.warm()
        if not (warmed and loop.realtime == "fifo"):  # a spare asked before it blocked
            loop.realtime = try_realtime_priority() if setup.realtime_priority else "off"
        if in_process:
            # The loop makes no reference cycles: refcounting frees everything, and a
            # collection of the whole heap would stall a tick for milliseconds.
            gc.collect()
            gc.freeze()
            gc.disable()
        if devices is not None:
            devices.open()
        loop.run()
    finally:
        loop.close()
        latch.close()
        if board is not None:
            board.close()
