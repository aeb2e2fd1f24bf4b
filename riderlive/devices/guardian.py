"""The guardian: a dead-man process that parks the devices when their controller dies.

The tick (or ``riderlive rig --drive``) drives the devices; the web process serves
operators. Either can die or hang: SIGKILL, SIGSTOP, an exception loop, the OOM
killer. The guardian is a third process, in its own session (a Ctrl-C in the terminal
does not reach it), that shares nothing with them but the safety board and the e-stop
latch in shared memory. It holds no bus while things are well.

It watches (every ``POLL_S``, and at once through pidfds when a process exits):

- the tick: gone, or its heartbeat older than ``tick_timeout_s``;
- the web process (when there is one): gone, or its heartbeat older than ``web_timeout_s``.

On either it performs a category 1 stop (IEC 60204-1) for the tick generation that
failed: SIGKILL the tick if it still runs (so two writers never share a bus), lend its
exiting threads this process's priority (a killed process drops its port lock only after
freeing its memory: ``devices/exiting.py``), read each device's last published state and
pose, mark the stop begun (``guardian_taking``: the web process may now start the next
generation, whose devices wait for the hand-back), take each device's transport (an
exclusive lock that the dead tick released with its file), and
per device in parallel: if it was moving, ease from its last published goal pose to
park over the plug's park time, then outputs off; in any case read the outputs back
and repeat outputs-off until every unit reports off, or the port is gone. An e-stop
requested meanwhile cuts the park short (outputs off at once). Then it releases the
transports and marks the generation stopped (``guardian_done``): the hand-back, after which
the new generation's devices connect (and stay disarmed). With the web process gone there is nothing to
hand back to: it repeats outputs-off until confirmed or for ``GIVE_UP_AFTER_S``, then exits.

What it cannot do is in docs/hardware.md (the guardian dying too, a pulled USB cable,
power loss): a hardware e-stop that cuts servo power is required near people.

    python -m riderlive.devices.guardian --board NAME --latch NAME --device JSON ...
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import select
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Sequence

from riderlive.devices.board import GUARDIAN_HANG_S, GuardianReport, SafetyBoard
from riderlive.devices.device import Device
from riderlive.devices.exiting import hasten_exit, holders
from riderlive.devices.latch import StopLatch
from riderlive.devices.lifecycle import DeviceState, FaultKind, PortBusy, PortLost
from riderlive.devices.registry import DeviceSpec, make_plug
from riderlive.devices.shared import pid_alive
from riderlive.sched import try_realtime_priority

log = logging.getLogger("riderlive.guardian")
POLL_S = 0.005
"""How often heartbeats are checked (deaths wake the guardian at once)."""
HANDBACK_AFTER_S = 2.0
"""With the web process alive, stop repeating an unconfirmed outputs-off after this and
hand the bus back (the new tick repeats it while it connects)."""
GIVE_UP_AFTER_S = 10.0
"""With no web process to hand back to, stop repeating an unconfirmed outputs-off after
this and exit: a bus that has not confirmed in 10 s is silent (emulator gone, servo
power cut, a port now owned by someone else); the servos' Bus Watchdog and the hardware
e-stop are all that is left, and an orphan guardian writing to a reused port forever
would be a hazard of its own."""
KILL_WAIT_S = 2.0
LATE_S = 0.05
"""A standby's look that wakes this much later than its poll period saw a host stall."""
PORT_RELEASE_S = 5.0
"""How long a transport held by another process (the tick just killed, whose file the
kernel has not released yet) is waited for before this stop gives up on it (logged with
the holder's pid); the next tick's connect then waits for it, and faults
(``setup_timeout``) if it stays held."""


class Guardian:
    """The watch loop and the stop; :meth:`run` returns when there is nothing left to guard."""

    def __init__(
        self,
        board: SafetyBoard,
        latch: StopLatch,
        specs: Sequence[DeviceSpec],
        tick_timeout_s: float,
        web_timeout_s: float,
        *,
        give_up_s: float = GIVE_UP_AFTER_S,
    ) -> None:
        self.board = board
        self.give_up_s = give_up_s
        self.latch = latch
        self.specs = list(specs)
        self.tick_timeout_s = tick_timeout_s
        self.web_timeout_s = web_timeout_s
        self.exit = False
        self._pidfds: dict[int, int] = {}
        for spec in self.specs:  # pay imports and validation now, not in an emergency
            make_plug(spec)

    def run(self) -> int:
        board = self.board
        board.guardian_pid = os.getpid()
        board.guardian_beat = time.perf_counter()
        board.guardian_ready = 1.0
        log.info("watching %s", ", ".join(s.name for s in self.specs))
        while not self.exit and not board.shutdown:
            now = time.perf_counter()
            board.guardian_beat = now
            generation = int(board.tick_generation)
            web_why = self._web_failed(now)
            pending = generation > board.guardian_done and board.tick_clean_exit != generation
            begun = int(board.guardian_taking)
            if generation > begun > board.guardian_done:  # a stop begun by a guardian that died: finish it
                self.stop(begun, f"generation {begun}'s stop was not finished", kill=False)
            elif pending:
                why = self._tick_failed(now) or web_why
                if why:
                    self.stop(generation, why)
                    if web_why or not board.web_pid:
                        return 0  # nobody left to hand the bus back to
            elif web_why:
                log.warning("%s; no tick to stop: exiting", web_why)
                return 0
            self._wait()
        return 0

    def _web_failed(self, now: float) -> str | None:
        return self._failed("web", self.board.web_pid, self.board.web_beat, self.web_timeout_s, now)

    def _tick_failed(self, now: float) -> str | None:
        return self._failed("tick", self.board.tick_pid, self.board.tick_beat, self.tick_timeout_s, now)

    @staticmethod
    def _failed(process: str, pid: int, beat: float, timeout_s: float, now: float) -> str | None:
        """Why the ``web`` or ``tick`` process (``pid``, last beat ``beat``) counts as failed (None: it does not)."""
        if not pid:
            return None
        if not pid_alive(pid):
            return f"the {process} process {pid} is gone"
        if beat and now - beat > timeout_s:
            return f"the {process} process {pid} has not beaten for {(now - beat) * 1000:.0f} ms"
        return None

    def _wait(self) -> None:
        """Sleep ``POLL_S``, waking at once when a watched process exits."""
        wanted = {int(self.board.web_pid), int(self.board.tick_pid)} - {0}
        for pid in set(self._pidfds) - wanted:
            os.close(self._pidfds.pop(pid))
        for pid in wanted - set(self._pidfds):
            with contextlib.suppress(OSError):
                self._pidfds[pid] = os.pidfd_open(pid)
        with contextlib.suppress(OSError, ValueError):
            select.select(list(self._pidfds.values()), [], [], POLL_S)

    # -- the stop ---------------------------------------------------------------------------

    def stop(self, generation: int, why: str, kill: bool = True) -> None:
        """Category 1 stop of every device of tick ``generation`` (``kill``: SIGKILL the
        board's tick first; False when finishing a dead guardian's stop: the board's tick is
        then the next generation, its devices waiting for this stop's hand-back)."""
        board = self.board
        log.critical("%s: category 1 stop of %s", why, ", ".join(s.name for s in self.specs))
        board.guardian_busy = 1.0
        try:
            if kill:
                self._kill_tick()
            lasts = [board.device(i) for i in range(len(self.specs))]
            board.guardian_taking = generation  # the next generation may tick: its devices wait for guardian_done
            threads = [
                threading.Thread(target=self._stop_device, args=(i, spec, last), name=f"guardian {spec.name}")
                for i, (spec, last) in enumerate(zip(self.specs, lasts, strict=True))
            ]
            for thread in threads:
                thread.start()
            for thread in threads:
                while thread.is_alive():  # beating meanwhile: a long park is not a hang
                    board.guardian_beat = time.perf_counter()
                    thread.join(POLL_S)
        finally:
            board.guardian_takeovers += 1
            board.guardian_done = generation
            board.guardian_busy = 0.0

    def _kill_tick(self) -> None:
        pid = int(self.board.tick_pid)
        if pid_alive(pid):
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
            deadline = time.perf_counter() + KILL_WAIT_S
            while pid_alive(pid) and time.perf_counter() < deadline:
                time.sleep(0.0005)
        if raised := hasten_exit(pid):
            log.info(
                "the tick %d exits (its port is released after its memory): %d threads raised to ours", pid, raised
            )

    def _stop_device(self, index: int, spec: DeviceSpec, last: tuple[DeviceState, list[float]] | None) -> None:
        if last is None:
            self.board.report(index, GuardianReport.NOT_CONNECTED)
            return  # never connected by that tick: nothing of ours on its bus
        state, pose = last
        self.board.report(index, GuardianReport.PARKING if state.moving else GuardianReport.STOPPING)
        device = Device(make_plug(spec), spec.period_s, self.latch)
        if not self._take(device, spec, pose, state.moving):
            self.board.report(index, GuardianReport.UNREACHABLE)
            return
        off_since: float | None = None
        next_tick = time.perf_counter()
        try:
            while True:
                now = time.perf_counter()
                status = device.tick(None, now)
                self.board.publish(index, device.state, device.plug.pose)  # a successor goes on from here
                if device.fault is not None and device.fault.kind is FaultKind.PORT_LOST:
                    log.error("%s: the port went away during the stop", spec.name)
                    self.board.report(index, GuardianReport.UNREACHABLE)
                    return
                if not device.state.moving:
                    if status.outputs_off_confirmed:
                        log.warning("%s: stopped, outputs off (read back)", spec.name)
                        self.board.report(index, GuardianReport.OUTPUTS_OFF)
                        return
                    off_since = now if off_since is None else off_since  # the read-back's time starts here
                    web = int(self.board.web_pid)
                    handback = bool(web and pid_alive(web))
                    if now - off_since > (HANDBACK_AFTER_S if handback else self.give_up_s):
                        log.error(
                            "%s: outputs-off not confirmed in %.1f s of read-backs; %s",
                            spec.name,
                            now - off_since,
                            "handing the bus back" if handback else "giving up (the servos' watchdog holds them)",
                        )
                        self.board.report(index, GuardianReport.UNCONFIRMED)
                        return
                next_tick += spec.period_s
                time.sleep(max(0.0, next_tick - time.perf_counter()))
        finally:
            device.plug.close()

    def _take(self, device: Device, spec: DeviceSpec, pose: list[float], moving: bool) -> bool:
        """Open the transport (waiting up to ``PORT_RELEASE_S`` for a killed holder's file
        to be released) and start the stop; False when it cannot be taken."""
        deadline = time.perf_counter() + PORT_RELEASE_S
        waited = False
        while True:
            try:
                device.takeover(pose, moving)
                if waited:
                    log.warning("%s: the transport was released: taken over", spec.name)
                return True
            except PortBusy:
                if time.perf_counter() > deadline:
                    log.error(
                        "%s: the transport stays held by %s for %.0f s: cannot stop it (the next tick's connect "
                        "waits for it, then faults)",
                        spec.name,
                        holders(spec.port) or "another process",
                        PORT_RELEASE_S,
                    )
                    return False
                waited = True
                time.sleep(0.005)
            except PortLost as exc:
                log.error("%s: %s: the port is gone (the servos' own watchdog is all that is left)", spec.name, exc)
                return False


def launch(
    board: str,
    latch: str,
    specs: Sequence[DeviceSpec],
    tick_timeout_s: float,
    web_timeout_s: float,
    *,
    give_up_s: float = GIVE_UP_AFTER_S,
    standby_after: int = 0,
    priority: int = 0,
) -> subprocess.Popen[bytes]:
    """Start the guardian in its own session (signals to the terminal's group skip it);
    ``standby_after``: a standby that waits, imports paid and plugs built, to become the
    guardian when guardian ``standby_after`` (or the one that follows it) is gone;
    ``priority``: SCHED_FIFO priority once its imports are paid (0: normal scheduling)."""
    args = [sys.executable, "-m", "riderlive.devices.guardian", "--board", board, "--latch", latch]
    args += ["--tick-timeout", repr(tick_timeout_s), "--web-timeout", repr(web_timeout_s)]
    args += ["--give-up", repr(give_up_s)] + (["--standby-after", str(standby_after)] if standby_after else [])
    args += ["--priority", str(priority)] if priority else []
    for spec in specs:
        args += ["--device", spec.to_json()]
    return subprocess.Popen(args, start_new_session=True, stdin=subprocess.DEVNULL)


def stand_by(board: SafetyBoard, after: int, poll_s: float = POLL_S) -> bool:
    """A standby guardian, its imports paid and its plugs built: wait until the active
    guardian (the board's, or ``after`` until that one has written its pid) is gone (at
    once through a pidfd) or hung, then become it (True), or until shutdown (False). Its
    heartbeat comes before its pid, so nobody sees the new pid with the old guardian's
    stale beat.

    Hung: a ready guardian whose beat is older than ``GUARDIAN_HANG_S`` while this
    standby itself ran on time (a look that woke later than ``poll_s`` + ``LATE_S`` is a
    host stall that stopped the guardian too: it is given the next look to beat). A hung
    guardian is killed (SIGKILL; it cannot be trusted to wake in the middle of a stop)
    and the standby takes over: with the tick hung as well, nobody else would park."""
    pidfd: int | None = None
    watched = 0
    last_look = time.perf_counter()
    try:
        while not board.shutdown:
            active = int(board.guardian_pid) or after
            now = time.perf_counter()
            on_time, last_look = now - last_look <= poll_s + LATE_S, now
            age = now - board.guardian_beat
            if on_time and board.guardian_pid == active and board.guardian_ready == 1.0 and age > GUARDIAN_HANG_S:
                log.critical("the guardian %d has not beaten for %.0f ms: killed; taking over", active, age * 1e3)
                with contextlib.suppress(ProcessLookupError):
                    os.kill(active, signal.SIGKILL)
                deadline = now + KILL_WAIT_S
                while pid_alive(active) and time.perf_counter() < deadline:
                    time.sleep(0.0005)
            if not pid_alive(active):
                board.guardian_beat = time.perf_counter()
                board.guardian_pid = os.getpid()
                board.guardian_standby = 0
                log.warning("the guardian %d is gone: the standby %d takes over", active, os.getpid())
                return True
            if active != watched:
                if pidfd is not None:
                    os.close(pidfd)
                pidfd, watched = None, active
                with contextlib.suppress(OSError):
                    pidfd = os.pidfd_open(active)
            with contextlib.suppress(OSError, ValueError):
                select.select([] if pidfd is None else [pidfd], [], [], poll_s)
        return False
    finally:
        if pidfd is not None:
            os.close(pidfd)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="riderlive-guardian", description=__doc__)
    parser.add_argument("--board", required=True)
    parser.add_argument("--latch", required=True)
    parser.add_argument("--device", action="append", default=[], help="a DeviceSpec as JSON")
    parser.add_argument("--tick-timeout", type=float, default=0.1)
    parser.add_argument("--web-timeout", type=float, default=1.0)
    parser.add_argument("--give-up", type=float, default=GIVE_UP_AFTER_S, help="see GIVE_UP_AFTER_S")
    parser.add_argument("--standby-after", type=int, default=0, metavar="PID", help="stand by for guardian PID")
    parser.add_argument("--priority", type=int, default=0, help="SCHED_FIFO priority once ready (0: normal)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s guardian: %(message)s")
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    board, latch = SafetyBoard(args.board), StopLatch(args.latch)
    if not args.standby_after:
        board.guardian_beat = time.perf_counter()  # alive from here (ready once the plugs are built)
        board.guardian_pid = os.getpid()
    guardian = Guardian(
        board,
        latch,
        [DeviceSpec.from_json(d) for d in args.device],
        args.tick_timeout,
        args.web_timeout,
        give_up_s=args.give_up,
    )

    def on_term(signum: int, frame: object) -> None:
        guardian.exit = True  # after any stop in progress

    signal.signal(signal.SIGTERM, on_term)
    if args.priority:  # after the imports and the plugs: a start at SCHED_FIFO would starve the web process
        try_realtime_priority(args.priority, who="the standby guardian" if args.standby_after else "the guardian")
    if args.standby_after:
        board.guardian_standby = os.getpid()  # ready to take over from here
    try:
        if args.standby_after and not stand_by(board, args.standby_after):
            return 0
        return guardian.run()
    finally:
        board.close()
        latch.close()


if __name__ == "__main__":
    raise SystemExit(main())
