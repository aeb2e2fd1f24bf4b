"""Keeping the tick alive: death and hang detection, warm failover, the guardian.

The web process supervises the tick process it spawned:

- **dead**: the process's sentinel becomes readable the moment it exits (SIGKILL, an
  exception, the OOM killer): noticed at once, on the event loop.
- **hung**: its heartbeat on the safety board (written every tick) is older than
  ``tick.hang_ticks - 1`` periods, checked every half period, but never sooner than
  ``tick.hang_floor_realtime`` (30 ms) when the tick runs at real-time priority,
  ``tick.hang_floor`` (0.25 s) when it does not, nor sooner than a device's longest
  legitimate wait plus those periods (``DeviceSpec.longest_wait_s``). The age is first
  discounted by what the host, not the tick, explains (``service/stall.py``: the
  supervisor's own wake-up lateness, the tick's run-queue wait from ``/proc``, the
  guardian's stalled heartbeat): a host stall is counted (``stalls``), never punished;
  nor is the time the tick spent asleep in device waits it declared, up to each one's
  deadline (``io_waits_excused``, ``devices/iowait.py``). A hang's log line and ``last_hang`` say what the tick's
  threads were doing (state, kernel wait channel, CPU and run-queue time since the beat).
  A stopped tick (SIGSTOP) is not excused. A hung tick is killed (SIGKILL) before
  anything else touches its bus.
- **starting**: a tick that has not beaten yet is never killed while it makes progress
  (CPU time or run-queue wait growing); only one stuck for ``stall.Model.start_stuck``.

Then the guardian (when devices are configured) parks the devices and releases their
buses. The supervisor waits only until it has *begun* that stop (``Guardians.taken``),
names the generation to hand back on the board (``handback_from``) and promotes the warm
spare (:meth:`TickLink.promote`) with the settings and the dead generation's state, so
rider frames flow while the park goes on; the new devices stay ``connecting``, transports
untouched, until the guardian reports the stop ended (``devices/setup_run.py``). A new
spare warms once the new generation beats. Failures in a row (death before the first
heartbeat or within ``STABLE_S`` of it) wait ``tick.restart_backoff``, doubling, from the
second on. The new tick leaves its devices ``disarmed`` (or ``estop``): nothing re-arms.
It starts with the settings applied since start (:meth:`TickLink.apply`), unless the last
one failed by itself before its first heartbeat: then as configured (``setups_dropped``),
so a setting that kills a tick at start cannot make a crash loop.

Status: ``up`` (``riderlive_tick_up``, ``/readyz``) only from the serving generation's
first heartbeat; from a failure until then the status says the tick is down and shows each
device as the guardian reports it (``realtime/down.py``). ``/api/state`` (``supervision``)
and ``/healthz`` say the rest.

The supervisor also keeps the guardian and its standby (``devices/guardians.py``) and
answers the web side of e-stops and of requests that want a reply (``service/requests.py``).
"""

from __future__ import annotations

import asyncio
import logging
import multiprocessing
import os
import time
from collections.abc import Callable
from typing import Any

from riderlive.devices.guardians import Guardians, GuardianTimes, handback_wanted
from riderlive.devices.latch import StopSource
from riderlive.realtime import commands as cmd
from riderlive.realtime.link import TickLink, exit_reason
from riderlive.service import stall
from riderlive.service.config import ServiceConfig
from riderlive.service.requests import TickRequests
from riderlive.service.spares import SpareKeeper
from riderlive.service.watch import BeatWatch

log = logging.getLogger(__name__)
STABLE_S = 5.0
"""A tick that has beaten this long ends a run of failures (the next one costs no backoff)."""
MAX_BACKOFF_S = 30.0
UNHEALTHY_AFTER_S = 60.0
"""``/healthz`` fails when the tick has been down this long (the supervisor cannot bring it back)."""
WARMUP_S, WARMUP_HANG_S = 3.0, 1.0
"""For its first seconds of ticking a tick may stall up to ``WARMUP_HANG_S`` (first calls
of compiled kernels, page faults) without being taken for hung, unless a device moves."""
OWN_FAILURES = ("exit", "SIGSEGV", "SIGABRT", "SIGBUS", "SIGFPE", "SIGILL")
"""Exit reasons that are the tick's own failure (not a kill from outside): at start they drop the applied settings."""


def web_priority() -> int:
    """This (the web) process's SCHED_FIFO priority now; 0: normal scheduling."""
    if not hasattr(os, "sched_getscheduler") or os.sched_getscheduler(0) & 0xFF != os.SCHED_FIFO:
        return 0
    return int(os.sched_getparam(0).sched_priority)


class TickSupervisor:
    """See the module docstring. Lives on the web process's event loop."""

    def __init__(
        self,
        link: TickLink,
        config: ServiceConfig,
        on_tick: Callable[[], None],
        publish_status: Callable[[dict[str, Any]], None],
        on_setup_dropped: Callable[[], None] = lambda: None,
    ) -> None:
        self.link = link
        self.config = config
        self.on_tick = on_tick
        self.publish_status = publish_status
        self.on_setup_dropped = on_setup_dropped
        """Called when a restart falls back to the configured settings (the service resets what it reports)."""
        self.setups_dropped = 0
        self.period = 1.0 / config.tick.rate
        self.hang_s = (config.tick.hang_ticks - 1.0) * self.period
        self.device_wait_s = max((d.longest_wait_s for d in link.setup.devices), default=0.0)
        """The longest a tick may block in a device's call (s): the hang threshold adds it."""
        self.up = False
        """The serving generation has beaten (``riderlive_tick_up``, ``/readyz``)."""
        self.stopping = False
        self.restarts = 0
        self.deaths = 0
        self.hangs = 0
        self.tally = stall.Tally()
        """Gaps counted, not punished (host stalls, declared device waits); the last hang's detail."""
        self.last_exit: str | None = None
        self.last_outage: float | None = None
        """Seconds from the last failure to the next generation's first heartbeat."""
        self.started_at = time.perf_counter()
        self._first_beat: float | None = None
        self.watch = BeatWatch(self.period, self.started_at)
        self.down_since: float | None = None
        self.promoted_at: float | None = None
        """When the next generation was last told to take over (perf_counter s)."""
        self.last_down_at: float | None = None
        """When the tick was last found dead or hung (perf_counter s; kept after the restart)."""
        self._streak = 0
        self._recovery: asyncio.Task[None] | None = None
        self._watch_task: asyncio.Task[None] | None = None
        self._bound: list[int] = []
        self.tick_requests = TickRequests(link, lambda: self._recovery is not None, lambda: self.last_exit)
        g = config.guardian
        times = GuardianTimes(g.tick_timeout, g.web_timeout, g.give_up, g.priority)
        self.guardians = Guardians(link.board, link.latch.name, link.setup.devices, times)
        self.spares = SpareKeeper(link)

    @property
    def supervised(self) -> bool:
        return self.link.sentinel is not None

    @property
    def guardian_wanted(self) -> bool:
        return bool(self.link.setup.devices) and self.config.guardian.enabled

    # -- start and stop ------------------------------------------------------------------

    async def start(self) -> None:
        self._bind()
        if self.guardian_wanted:
            self.guardians.start()
        self._watch_task = asyncio.get_running_loop().create_task(self._watch())

    async def stop(self) -> None:
        """Before the link stops: no recovery from here on."""
        self.stopping = True
        for task in (self._watch_task, self._recovery):
            if task is not None:
                task.cancel()
        self._unbind()

    def _bind(self) -> None:
        loop = asyncio.get_running_loop()
        loop.add_reader(self.link.notify_fd, self.on_tick)
        loop.add_reader(self.link.commands_fd, self.tick_requests.on_replies)
        self._bound = [self.link.notify_fd, self.link.commands_fd]
        sentinel = self.link.sentinel
        if sentinel is not None:
            loop.add_reader(sentinel, self._on_exit)
            self._bound.append(sentinel)

    def _unbind(self) -> None:
        loop = asyncio.get_running_loop()
        for fd in self._bound:
            loop.remove_reader(fd)
        self._bound = []

    # -- detection -----------------------------------------------------------------------

    def _on_exit(self) -> None:
        """The tick process's sentinel is readable (it has exited), or it is being torn down."""
        if self.stopping or self._recovery is not None:
            return
        self.deaths += 1
        reason = self.link.exit_reason()
        self._begin_recovery(f"died ({'killed or exiting' if reason == 'running' else reason})", died=True)

    async def _drop_settings_if_they_killed_it(self) -> None:
        """A generation that died before its first heartbeat by its own failure (an exit status,
        a crash signal; not a kill from outside) with the settings applied since start (a
        preset, a gait): the next one starts as configured, not into a crash loop."""
        link = self.link
        if link.generation == 1 or self._first_beat is not None:
            return
        await asyncio.to_thread(link.process.join, 2.0)  # its exit status (it may still be torn down)
        reason = link.exit_reason()
        if reason.startswith(OWN_FAILURES) and link.forget_applied():
            self.setups_dropped += 1
            self.last_exit = f"died ({reason}) before ticking: the next one starts with the configured settings"
            log.error("the tick %s", self.last_exit)
            self.on_setup_dropped()

    async def _watch(self) -> None:
        """Every half period: the web heartbeat, the tick (``_check_tick``), the spare, the guardian."""
        interval = max(self.period / 2.0, 0.005)  # the hang floors are >= 30 ms: 5 ms is fine grain
        board = self.link.board
        due = time.perf_counter()
        while not self.stopping:
            due += interval
            await asyncio.sleep(max(0.0, due - time.perf_counter()))
            now = time.perf_counter()
            woke_late = max(0.0, now - due)
            if woke_late > interval:
                due = now  # a stall of our own: do not run the missed checks back to back
            board.web_beat = now
            if self._recovery is None and self.supervised:
                self._check_tick(now, woke_late)
            if self._first_beat is not None and now - self._first_beat > STABLE_S:
                self._streak = 0
            self.spares.check(now, self.up and self._recovery is None)
            if not self.stopping:
                self.guardians.check(now)

    def _check_tick(self, now: float, woke_late: float) -> None:
        """One look at the tick (``service/watch.py``): its first heartbeat, a hang, a stall (``service/stall.py``)."""
        link, watch, board = self.link, self.watch, self.link.board
        guardian_beat = board.guardian_beat if self.guardians.guardian is not None else 0.0
        beat, pid = board.tick_beat, board.tick_pid
        io = (board.tick_io_until, board.tick_io_since, board.tick_io_waited)
        observation = watch.observe(now, woke_late, beat, pid, guardian_beat, io=io)
        if watch.beaten and self._first_beat is None:
            self._on_first_beat(now)
        finding = stall.classify(stall.Model(self.hang_threshold()), observation)
        if finding.verdict is stall.Verdict.DYING or not link.alive():
            self._on_exit()  # killed or exiting, its sentinel not readable yet: a death, not a hang
        elif finding.verdict in (stall.Verdict.HUNG, stall.Verdict.NEVER_STARTED):
            self.hangs += 1
            self.tally.last_hang = stall.hang_detail(finding, observation, pid)
            self._begin_recovery(self.tally.last_hang)
        elif (line := self.tally.add(finding, beat, observation.beat_age or 0.0)) is not None:
            log.warning(line)

    def _on_first_beat(self, now: float) -> None:
        """The serving generation has beaten: up, and a new spare warms in the background."""
        self._first_beat = now
        self.up = True
        self.link.mark_up()
        if self.last_down_at is not None and self.down_since is not None:
            self.last_outage = now - self.down_since
            log.warning(
                "tick generation %d is up, %.0f ms after the failure", self.link.generation, self.last_outage * 1000
            )
        self.down_since = None
        self.publish_status({**self.link.status(), "tick_up": True, "restarting": False})
        self.spares.next_at = now

    def hang_threshold(self) -> float:
        """Seconds without a heartbeat that make a tick hung (see the module docstring)."""
        tick = self.config.tick
        realtime = self.link.counters.values[self.link.counters.index["realtime"]] == 1.0
        floor = tick.hang_floor_realtime if realtime else tick.hang_floor
        threshold = max(self.hang_s + self.device_wait_s, floor)
        if not self.spares.warm():
            # No warm spare: a failover would be a cold start (seconds on a busy host), dearer
            # than most stalls; a moving device is the guardian's (``guardian.tick_timeout``).
            threshold = max(threshold, tick.hang_floor)
            if not self._a_device_moves():  # a cold start costs seconds; a moving device is the guardian's
                threshold = max(threshold, tick.hang_floor_cold)
        first = self._first_beat
        if (first is None or time.perf_counter() - first < WARMUP_S) and not self._a_device_moves():
            threshold = max(threshold, WARMUP_HANG_S)
        return threshold

    def _a_device_moves(self) -> bool:
        """A device of this tick is armed and moving (the safety board): no warm-up
        leniency then, since a stalled tick is a rig moving without a controller."""
        board = self.link.board
        for i in range(len(self.link.setup.devices)):
            published = board.device(i)
            if published is not None and published[0].moving:
                return True
        return False

    def _begin_recovery(self, why: str, died: bool = False) -> None:
        self.up = False
        self.down_since = self.last_down_at = time.perf_counter()
        self.last_exit = why
        log.critical("the tick %s: its devices are being stopped; failing over", why)
        self.link.mark_down(why)
        self.publish_status({**self.link.status(), "restarting": True})
        self.tick_requests.fail_all(f"the tick {why}")
        self._recovery = asyncio.get_running_loop().create_task(self._recover(died))

    async def _wait_for_the_guardian(self, generation: int) -> None:
        """Until the guardian has begun the stop of that generation's devices (killed the tick,
        read their last poses: milliseconds), not until it ends; the next generation's devices
        wait for the hand-back (``board.handback_from``). Bounded: a guardian that dies
        meanwhile is relaunched and takes the stop. When no guardian has begun it by the
        bound, nobody will park those devices: the next generation connects them at once,
        and its setup turns their outputs off (a category 0 stop, not a rig left holding its
        last goal with torque on)."""
        guardians, board = self.guardians, self.link.board
        deadline = time.perf_counter() + guardians.stop_wait_s(self.config.rig.park_timeout)
        while not (taken := guardians.taken(generation)):
            if time.perf_counter() > deadline:
                log.error(
                    "no guardian began the stop of generation %d in time: the next generation connects its "
                    "devices at once and turns their outputs off",
                    generation,
                )
                break
            await asyncio.sleep(0.002)
        board.handback_from = handback_wanted(generation, taken, guardians.stopped(generation))

    async def _recover(self, died: bool) -> None:
        link = self.link
        self._unbind()
        if not died:
            link.kill()  # SIGKILL: it runs none of its code once that returns (reaped later)
        if died:
            await self._drop_settings_if_they_killed_it()
        await self._wait_for_the_guardian(link.generation)
        if self._streak:  # failures in a row: back off (a first failure costs none)
            await asyncio.sleep(min(self.config.tick.restart_backoff * 2 ** (self._streak - 1), MAX_BACKOFF_S))
        self._streak += 1
        if self.stopping:
            return
        dead = link.process
        warm = link.promote()
        self.promoted_at = time.perf_counter()
        self._bind()
        self.restarts += 1
        self.started_at = time.perf_counter()
        self._first_beat = None
        self.watch.reset(self.started_at)
        self._recovery = None
        log.warning(
            "tick generation %d started from %s: devices connect and stay disarmed",
            link.generation,
            "the warm spare" if warm else "cold",
        )
        self.publish_status({**link.status(), "restarting": True})
        if (
            died
            and isinstance(dead, multiprocessing.process.BaseProcess)
            and "killed or exiting" in str(self.last_exit)
        ):
            await asyncio.to_thread(dead.join, 2.0)  # torn down by now, or soon: its exit status for the record
            if dead.exitcode is not None:
                self.last_exit = f"died ({exit_reason(dead.exitcode)})"

    # -- e-stop and requests (``service/requests.py``) ------------------------------------

    def estop(self, source: StopSource) -> float:
        """Latch an e-stop (shared memory, at once) and wake the tick; the request time."""
        return self.tick_requests.estop(source)

    async def ask(self, build: Callable[[int], cmd.Request], timeout: float = 2.0) -> cmd.Reply:
        """Send a request to the tick and wait for its reply (a ``tick_down`` refusal if it cannot)."""
        return await self.tick_requests.ask(build, timeout)

    def stop_guardian(self) -> None:
        """After the tick has stopped (its devices are closed): the guardian may go."""
        self.guardians.stop()

    # -- reporting -----------------------------------------------------------------------

    def ready(self) -> bool:
        """Ticking now: up and a heartbeat within the hang threshold."""
        age = self.link.beat_age()
        return self.up and age is not None and age <= max(self.hang_threshold(), 0.25)

    def live(self) -> bool:
        """Not stuck: the tick is up, or has been down for less than ``UNHEALTHY_AFTER_S``."""
        return self.down_since is None or time.perf_counter() - self.down_since < UNHEALTHY_AFTER_S

    def snapshot(self) -> dict[str, Any]:
        board = self.link.board
        return {
            "up": self.up,
            "generation": self.link.generation,
            "tick_pid": board.tick_pid,
            "restarts": self.restarts,
            "deaths": self.deaths,
            "hangs": self.hangs,
            **self.tally.snapshot(),
            "takeovers": self.link.takeovers,
            "last_outage": self.last_outage,
            "hang_threshold": self.hang_threshold(),
            "spare": self.spares.snapshot(),
            "setups_dropped": self.setups_dropped,
            "beats_unread": self.watch.beats_unread,
            "last_exit": self.last_exit,
            "down_for": None if self.down_since is None else time.perf_counter() - self.down_since,
            "down_since": self.down_since,
            "last_down_at": self.last_down_at,
            "promoted_at": self.promoted_at,
            "web_priority": web_priority(),
            "guardian": self.guardians.snapshot(self.guardian_wanted),
        }
