"""Keeping the tick alive: death and hang detection, restarts with backoff, the guardian.

The web process supervises the tick process it spawned:

- **dead**: the process's sentinel becomes readable the moment it exits (SIGKILL, an
  exception, the OOM killer): noticed at once, on the event loop.
- **hung**: its heartbeat on the safety board (written every tick) is older than
  ``tick.hang_ticks - 1`` periods, checked every half period: noticed within
  ``hang_ticks`` periods (SIGSTOP, a loop stuck in a call), but never sooner than
  ``tick.hang_floor_realtime`` (30 ms: up to 150 ticks/s that is within 5 ticks) when
  the tick runs at real-time priority, ``tick.hang_floor`` (0.25 s) when it does not (a
  loaded machine stalls a normal process for tens of ms: no false restarts), nor sooner
  than a device's longest legitimate wait plus those periods (``DeviceSpec.longest_wait_s``:
  a servo reply awaited to its ceiling, 27.5 ms for the default rig bus; before, a tick
  at 500 Hz waiting out one lost reply was killed as hung at 30 ms).
  A hung tick is killed (SIGKILL) before anything else touches its bus.

Then the guardian (when devices are configured) parks the devices and releases their
buses; the supervisor waits for that, then starts the next tick generation after a
backoff (``tick.restart_backoff``, doubling per failure in a row, reset after 30 s of
good ticking). The new tick connects its devices and leaves them ``disarmed`` (or
``estop`` while the latch is set): nothing is re-armed. It starts with the settings
applied since start (preset, animator layer, mode, gait: :meth:`TickLink.apply`); one
that dies before its first heartbeat with them makes the next start as configured
(``setups_dropped``; the service reports the configured settings again), so a setting
that kills a tick at start cannot make a crash loop. It all shows in the status
(``tick_up``, ``restarting``), ``/api/state`` (``supervision``), ``/metrics``
(``riderlive_tick_up``, ``riderlive_tick_restarts_total``) and ``/healthz`` / ``/readyz``.

The supervisor also launches the guardian, restarts it if it dies, and answers the
web side of e-stops (latch + wake) and of requests that want a reply (arm, disarm,
reset, reload).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import subprocess
import time
from collections.abc import Callable
from typing import Any

from riderlive.devices.board import guardian_watching
from riderlive.devices.guardian import launch
from riderlive.devices.latch import StopSource
from riderlive.devices.lifecycle import Refusal
from riderlive.realtime import commands as cmd
from riderlive.realtime.link import TickLink
from riderlive.service.config import ServiceConfig

log = logging.getLogger(__name__)
STABLE_S = 30.0
"""A tick that has run this long resets the backoff."""
MAX_BACKOFF_S = 30.0
UNHEALTHY_AFTER_S = 60.0
"""``/healthz`` fails when the tick has been down this long (the supervisor cannot bring it back)."""
START_GRACE_S = 60.0
"""A new tick may take this long to its first heartbeat (imports, compiling kernels)."""
WARMUP_S, WARMUP_HANG_S = 3.0, 1.0
"""For its first seconds of ticking a tick may stall up to ``WARMUP_HANG_S`` (first calls
of compiled kernels, page faults) without being taken for hung, unless a device moves."""
GUARDIAN_START_S = 5.0
"""Allowance for a guardian relaunched during a stop to start and finish it (its imports
on a loaded host), on top of the park timeout."""
_ids = itertools.count(1)


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
        self.beats_unread = 0
        """Heartbeat reads of 0 after the generation's first beat (should stay 0; see ``_watch``)."""
        self.period = 1.0 / config.tick.rate
        self.hang_s = (config.tick.hang_ticks - 1.0) * self.period
        self.device_wait_s = max((d.longest_wait_s for d in link.setup.devices), default=0.0)
        """The longest a tick may block in a device's call (s): the hang threshold adds it."""
        self.up = True
        self.stopping = False
        self.restarts = 0
        self.deaths = 0
        self.hangs = 0
        self.last_exit: str | None = None
        self.started_at = time.perf_counter()
        self._first_beat: float | None = None
        self._last_beat = 0.0
        """When the last heartbeat seen was written (perf_counter s)."""
        self.down_since: float | None = None
        self.last_down_at: float | None = None
        """When the tick was last found dead or hung (perf_counter s; kept after the restart)."""
        self._streak = 0
        self._recovery: asyncio.Task[None] | None = None
        self._watch_task: asyncio.Task[None] | None = None
        self._bound: list[int] = []
        self._pending: dict[int, asyncio.Future[cmd.Reply]] = {}
        self.guardian: subprocess.Popen[bytes] | None = None
        self.standby: subprocess.Popen[bytes] | None = None
        """A standby guardian: becomes the guardian the moment it is gone (guardian.py)."""
        self.guardian_restarts = 0
        self._guardian_launched_at = 0.0

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
            self._start_guardians()
        self._watch_task = asyncio.get_running_loop().create_task(self._watch())

    async def stop(self) -> None:
        """Before the link stops: no recovery from here on."""
        self.stopping = True
        for task in (self._watch_task, self._recovery):
            if task is not None:
                task.cancel()
        self._unbind()

    def stop_guardian(self) -> None:
        """After the tick has stopped (its devices are closed): the guardian may go."""
        self.link.board["shutdown"] = 1.0
        for guardian in (self.guardian, self.standby):
            if guardian is not None:
                try:
                    guardian.wait(2.0)
                except subprocess.TimeoutExpired:
                    guardian.kill()
                    guardian.wait(2.0)

    def _bind(self) -> None:
        loop = asyncio.get_running_loop()
        loop.add_reader(self.link.notify_fd, self.on_tick)
        loop.add_reader(self.link.commands_fd, self._on_replies)
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
        """The tick process's sentinel is readable: it has exited."""
        if self.stopping or self._recovery is not None:
            return
        self.link.process.join(0.1)
        self.deaths += 1
        why = f"died ({self.link.exit_reason()})"
        if self.link.generation > 1 and self._first_beat is None and self.link.forget_applied():
            # It died before its first heartbeat with the settings applied since start (a
            # preset, a gait): the next one starts as configured, not into a crash loop.
            self.setups_dropped += 1
            why += " before ticking: the next one starts with the configured settings"
            self.on_setup_dropped()
        self._begin_recovery(why)

    async def _watch(self) -> None:
        """Every half period: the web heartbeat, a hung tick, the guardian."""
        interval = max(self.period / 2.0, 0.005)  # the hang floors are >= 30 ms: 5 ms is fine grain
        board = self.link.board
        while not self.stopping:
            await asyncio.sleep(interval)
            now = time.perf_counter()
            board["web_beat"] = now
            if self.up and self._recovery is None and self.supervised:
                age = self.link.beat_age()
                if age is not None:
                    self._last_beat = now - age
                    if self._first_beat is None:
                        self._first_beat = now
                elif self._first_beat is not None:
                    # A generation that has beaten never reads "no beat" again (only a respawn
                    # clears it), yet one CI run restarted a ticking tick as "never started":
                    # counted, and the age is taken from the last beat seen (a hang still shows).
                    self.beats_unread += 1
                    age = now - self._last_beat
                if age is not None and age > self.hang_threshold():
                    self.hangs += 1
                    self._begin_recovery(f"hung (no heartbeat for {age * 1000:.0f} ms)")
                elif age is None and now - self.started_at > START_GRACE_S:
                    self.hangs += 1
                    self._begin_recovery(f"never started ticking in {START_GRACE_S:.0f} s")
            if self.up and now - self.started_at > STABLE_S:
                self._streak = 0
            self._check_guardian(now)

    def hang_threshold(self) -> float:
        """Seconds without a heartbeat that make a tick hung (see the module docstring)."""
        tick = self.config.tick
        realtime = self.link.counters.values[self.link.counters.index["realtime"]] == 1.0
        floor = tick.hang_floor_realtime if realtime else tick.hang_floor
        threshold = max(self.hang_s + self.device_wait_s, floor)
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

    def _begin_recovery(self, why: str) -> None:
        self.up = False
        self.down_since = self.last_down_at = time.perf_counter()
        self.last_exit = why
        log.critical("the tick %s: its devices are being stopped; restarting it", why)
        status = {**self.link.status(), "driver": "dead", "tick_alive": False, "tick_up": False}
        self.publish_status({**status, "restarting": True, "reason": why})
        for future in self._pending.values():
            if not future.done():
                future.set_result(cmd.Reply(0, False, {}, Refusal.TICK_DOWN.value, f"the tick {why}"))
        self._recovery = asyncio.get_running_loop().create_task(self._recover())

    async def _recover(self) -> None:
        link = self.link
        self._unbind()
        if link.alive():
            await asyncio.to_thread(link.kill)
        await self._wait_for_guardian(link.generation)
        delay = min(self.config.tick.restart_backoff * 2**self._streak, MAX_BACKOFF_S)
        self._streak += 1
        await asyncio.sleep(delay)
        if self.stopping:
            return
        link.respawn()
        self._bind()
        self.restarts += 1
        self.up = True
        self.started_at = time.perf_counter()
        self._first_beat = None
        self.down_since = None
        self._recovery = None
        log.warning("tick restarted (generation %d): devices connect and stay disarmed", link.generation)
        self.publish_status({**link.status(), "tick_up": True, "restarting": False, "generation": link.generation})

    async def _wait_for_guardian(self, generation: int) -> None:
        """Until the guardian has stopped that generation's devices (bounded)."""
        if self.guardian is None:
            return
        board = self.link.board
        deadline = time.perf_counter() + self.config.rig.park_timeout + 3.0 + GUARDIAN_START_S
        while time.perf_counter() < deadline:  # a guardian that dies meanwhile is relaunched and goes on
            if board["guardian_done"] >= generation:
                return
            await asyncio.sleep(0.01)
        log.error("the guardian did not report the stop of generation %d in time", generation)

    # -- the guardian --------------------------------------------------------------------

    def _launch_guardian(self, standby_after: int = 0) -> subprocess.Popen[bytes]:
        link, guardian = self.link, self.config.guardian
        return launch(
            link.board.name,
            link.latch.name,
            link.setup.devices,
            guardian.tick_timeout,
            guardian.web_timeout,
            give_up_s=guardian.give_up,
            standby_after=standby_after,
        )

    def _start_guardians(self) -> None:
        """The guardian, and a standby (imports paid, plugs built) that becomes the guardian
        within a few ms of its death: a relaunch would take a Python start and the imports."""
        self.guardian = self._launch_guardian()
        self._guardian_launched_at = time.perf_counter()
        self.standby = self._launch_guardian(standby_after=self.guardian.pid)

    def _check_guardian(self, now: float) -> None:
        """The guardian gone: its standby has taken over (or it is relaunched); a new standby
        follows (at most one launch a second)."""
        if self.guardian is None or self.stopping:
            return
        if self.guardian.poll() is not None:
            code = self.guardian.returncode
            if self.standby is not None and self.standby.poll() is None:
                log.critical("the guardian exited (%s): its standby %d takes over", code, self.standby.pid)
                self.guardian, self.standby = self.standby, None
            elif now - self._guardian_launched_at >= 1.0:
                log.critical("the guardian exited (%s), no standby: relaunching it; arming is refused", code)
                self.link.board["guardian_ready"] = 0.0
                self.guardian, self.standby = self._launch_guardian(), None
                self._guardian_launched_at = now
            else:
                return
            self.guardian_restarts += 1
        if (self.standby is None or self.standby.poll() is not None) and now - self._guardian_launched_at >= 1.0:
            self.standby = self._launch_guardian(standby_after=self.guardian.pid)
            self._guardian_launched_at = now

    def guardian_alive(self) -> bool:
        """Ready, its process alive, its heartbeat fresh (the tick's own test: board.guardian_watching)."""
        return guardian_watching(self.link.board, time.perf_counter()) is None

    # -- e-stop and requests -------------------------------------------------------------

    def estop(self, source: StopSource) -> float:
        """Latch an e-stop (shared memory, at once) and wake the tick; the request time."""
        at = self.link.latch.request(source)
        with contextlib.suppress(OSError, ValueError):  # a tick that is down: the latch holds,
            self.link.send(cmd.EStop())  # and the next one starts in estop
        return at

    async def ask(self, build: Callable[[int], cmd.Request], timeout: float = 2.0) -> cmd.Reply:
        """Send a request to the tick and wait for its reply."""
        if not self.up:
            return cmd.Reply(0, False, {}, Refusal.TICK_DOWN.value, f"the tick is restarting ({self.last_exit})")
        request = next(_ids)
        future: asyncio.Future[cmd.Reply] = asyncio.get_running_loop().create_future()
        self._pending[request] = future
        try:
            self.link.send(build(request))
            return await asyncio.wait_for(future, timeout)
        except (TimeoutError, OSError, ValueError):
            return cmd.Reply(request, False, {}, Refusal.TICK_DOWN.value, f"the tick did not answer in {timeout:g} s")
        finally:
            self._pending.pop(request, None)

    def _on_replies(self) -> None:
        for reply in self.link.replies():
            future = self._pending.get(reply.request)
            if future is not None and not future.done():
                future.set_result(reply)

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
            "tick_pid": int(board["tick_pid"]),
            "restarts": self.restarts,
            "deaths": self.deaths,
            "hangs": self.hangs,
            "setups_dropped": self.setups_dropped,
            "beats_unread": self.beats_unread,
            "last_exit": self.last_exit,
            "down_for": None if self.down_since is None else time.perf_counter() - self.down_since,
            "down_since": self.down_since,
            "last_down_at": self.last_down_at,
            "guardian": {
                "enabled": self.guardian_wanted,
                "alive": self.guardian_alive() if self.guardian is not None else False,
                "pid": None if self.guardian is None else self.guardian.pid,
                "standby_pid": None if self.standby is None or self.standby.poll() is not None else self.standby.pid,
                "standby_ready": self.standby is not None and board["guardian_standby"] == self.standby.pid,
                "restarts": self.guardian_restarts,
                "takeovers": int(board["guardian_takeovers"]),
            },
        }
