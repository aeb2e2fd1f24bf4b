"""``riderlive rig``: check a servo map; ``--drive`` it with the service's own tick loop.

    riderlive rig config/rigs/bench3.toml                         # validate, print the map and wire budget
    riderlive rig bench3 --port /dev/ttyUSB0 --drive 30           # connect, check, configure: disarmed, nothing moves
    riderlive rig bench3 --port /dev/ttyUSB0 --drive 30 --arm     # arm: soft start, trot 30 s, park, torque off

``--drive`` runs the tick of ``riderlive serve`` in this process: the same
:class:`~riderlive.realtime.tick.TickLoop` (``realtime/tick_process.serve``), built from the
same setup (``make_setup`` on a service configuration: a procedural horse at the rig's tick
rate, the rig its one device) on its own shared memory
(:class:`~riderlive.realtime.memory.TickMemory`). An operator thread (:class:`Operator`)
stands where the web process stands in ``serve``: it reads the tick's status, sends its
requests on the command pipe (the arm, the disarm when the time is up, the stop) and prints
the status once a second; each state change is printed as the device makes it.

Its safety is the service's: a guardian and a standby guardian (``devices/guardians.py``)
watch this process (its pid is the board's tick and web pid) and park the rig if it dies or
hangs (heartbeat older than :data:`TICK_TIMEOUT_S` plus the rig's longest legitimate wait);
the tick watches the guardian (dead, hung, or replaced by its standby: the tick parks the rig
itself and refuses to arm). Nothing moves without ``--arm`` (one arm request, as the page's
button sends). Ctrl-C (SIGINT) or SIGTERM is an e-stop: torque off at once (category 0),
read back until every servo confirms, then exit.

Exit status (:class:`Ending`): 0 the rig was driven for SECONDS and parked (or, without
``--arm``, connected and left disarmed); 1 a fault, or a stop nobody asked for (the arm
refused, the guardian lost: parked by the tick); 130 an e-stop; 2 a bad map.
"""

from __future__ import annotations

import argparse
import enum
import logging
import multiprocessing
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import orjson

from riderlive.channels import RIDER_PART_NAMES
from riderlive.configfile import ConfigError
from riderlive.devices.guardians import Guardians, GuardianTimes
from riderlive.devices.lifecycle import DeviceState
from riderlive.devices.registry import DeviceSpec, plan
from riderlive.dynamixel.rig import RIG_DIR, RigConfig, load_rig, wire_budget
from riderlive.realtime import commands as cmd
from riderlive.realtime.counters import TickCounters
from riderlive.realtime.memory import TickMemory
from riderlive.realtime.record import RecordLayout
from riderlive.realtime.tick_process import Signals, prepare, serve
from riderlive.rules.params import load_preset
from riderlive.service.config import GuardianSection, RigSection, ServiceConfig, SourceSection, TickSection
from riderlive.service.runtime import make_setup

log = logging.getLogger("riderlive.rig")
S = DeviceState
Say = Callable[[str], None]
TICK_TIMEOUT_S = 0.1
"""The guardian's hung-tick threshold for ``rig --drive`` (s), plus the rig's longest
legitimate wait: no supervisor watches this tick (``serve``'s kills a hung tick in 30 ms at
real-time priority), so the guardian's own threshold is the short one."""
GUARDIAN_START_S = 15.0
"""How long the guardian may take to start (its imports on a loaded host) before the drive gives up."""
ESTOP_READBACK_S = 5.0
"""After an e-stop, how long the torque-off read-back is waited for before exiting anyway."""
POLL_S = 0.01
"""How often the operator thread looks at the tick's status and the guardians."""


class Ending(enum.Enum):
    """How a drive ended, and its exit status."""

    LEFT_DISARMED = "left disarmed"
    PARKED = "parked"
    FAULT = "fault"
    UNASKED_STOP = "stopped without being asked"
    ESTOP = "e-stop"

    @property
    def exit_code(self) -> int:
        return {Ending.ESTOP: EXIT_ESTOP, Ending.FAULT: EXIT_FAULT, Ending.UNASKED_STOP: EXIT_FAULT}.get(self, 0)


EXIT_FAULT, EXIT_ESTOP = 1, 130


class Phase(enum.Enum):
    """The operator's side of a drive."""

    CONNECTING = "connecting"
    """Until the rig is first disarmed."""
    ARMING = "arming"
    """The arm request sent, its reply awaited."""
    DRIVING = "driving"
    """Armed: the time runs."""
    PARKING = "parking"
    """The time is up: the disarm sent."""
    STOPPING = "stopping"
    """The stop sent: the loop ends once the rig rests."""


@dataclass(frozen=True)
class DrivePlan:
    """What to drive and how: the rig's device, for ``seconds`` once armed, armed or not."""

    spec: DeviceSpec
    seconds: float
    arm: bool


class Operator:
    """The operator's side of the tick (what the web process is to ``serve``'s tick): reads
    its status blob, sends requests on the command pipe, keeps the guardians; one thread."""

    def __init__(
        self, memory: TickMemory, commands: Connection, plan: DrivePlan, guardians: Guardians | None, say: Say
    ) -> None:
        self.memory = memory
        self.commands = commands
        self.spec, self.seconds, self.arm = plan.spec, plan.seconds, plan.arm
        self.guardians = guardians
        self.say = say
        self.counters = TickCounters(memory.counters.values)
        self.phase = Phase.CONNECTING
        self.ending: Ending | None = None
        self.rig: dict[str, Any] = {}
        """The rig's last status (``DeviceStatus.to_dict``)."""
        self.why = ""
        """Why a drive ended unasked (a refused arm, the guardian lost)."""
        self.done = threading.Event()
        self._version = -1
        self._armed_at = 0.0
        self._estop_at: float | None = None
        self._guardian_lost: str | None = None
        self._losses = 0
        self._watching: tuple[int | None, int | None] = (None, None)
        self._next_print = 0.0
        self.start = time.perf_counter()

    def run(self) -> None:
        """Until the loop has ended (``done``); a failure of its own stops the tick."""
        try:
            while not self.done.wait(POLL_S):
                self.step(time.perf_counter())
        except Exception:
            log.exception("the operator thread failed: stopping the tick")
            self._stop(Ending.FAULT)

    def step(self, now: float) -> None:
        """One look: the guardians, the requests' replies, the status."""
        if self.guardians is not None:
            self.guardians.check(now)
            self._say_guardians()
        for reply in self._replies():
            self._on_reply(reply, now)
        status = self._status()
        if status is None or not status.get("rig"):
            return
        self.rig = status["rig"]
        self._say_guardian_watch(status.get("guardian"))
        self._decide(DeviceState(self.rig["state"]), now)
        if now >= self._next_print:
            self._next_print = now + 1.0
            self.say(self._summary(now))

    def _decide(self, state: DeviceState, now: float) -> None:
        phase = self.phase
        if phase is Phase.STOPPING:
            return
        if state is S.ESTOP:
            self._estop_at = now if self._estop_at is None else self._estop_at
            if self.rig["outputs_off_confirmed"] or now - self._estop_at > ESTOP_READBACK_S:
                self._stop(Ending.ESTOP)
        elif state is S.FAULT:
            self._stop(Ending.FAULT)
        elif phase is Phase.CONNECTING and state is S.DISARMED:
            if not self.arm:
                self.say("disarmed: connected, checked, configured, torque off. Nothing moves without --arm.")
                self._stop(Ending.LEFT_DISARMED)
            else:
                self.phase = Phase.ARMING
                self.commands.send(cmd.Arm(self.spec.name, "cli --arm", 1))
        elif phase is Phase.DRIVING and state is S.PARKED:
            self.why = f"parked by the tick: {self._guardian_lost or 'not asked by this command'}"
            self._stop(Ending.UNASKED_STOP)
        elif phase is Phase.PARKING and state is S.PARKED:
            self._stop(Ending.PARKED)
        elif phase is Phase.DRIVING and now - self._armed_at >= self.seconds:
            self.phase = Phase.PARKING
            self.commands.send(cmd.Disarm(self.spec.name, "cli: time is up", 2))

    def _on_reply(self, reply: cmd.Reply, now: float) -> None:
        if reply.request != 1 or self.phase is not Phase.ARMING:
            return
        if reply.ok:
            self.phase, self._armed_at = Phase.DRIVING, now
        else:
            self.why = f"not armed: {reply.message}"
            self.say(self.why)
            self._stop(Ending.UNASKED_STOP)

    def _stop(self, ending: Ending) -> None:
        if self.phase is Phase.STOPPING:
            return
        self.phase, self.ending = Phase.STOPPING, ending
        self.commands.send(cmd.Stop())

    def _replies(self) -> list[cmd.Reply]:
        out = []
        while self.commands.poll():
            message = self.commands.recv()
            if isinstance(message, cmd.Reply):
                out.append(message)
        return out

    def _status(self) -> dict[str, Any] | None:
        blob = self.memory.status_blob
        version = blob.version
        if version == self._version:
            return None
        data = blob.read()
        if data is None:
            return None
        self._version = version
        status: dict[str, Any] = orjson.loads(data)
        return status

    def _say_guardians(self) -> None:
        """Say who watches when it changes (a standby that took over, a new standby)."""
        guardians = self.guardians
        assert guardians is not None
        standby = guardians.standby
        watching = (
            None if guardians.guardian is None else guardians.guardian.pid,
            None if standby is None or standby.poll() is not None else standby.pid,
        )
        if watching != self._watching:
            self._watching = watching
            self.say(f"guardian {watching[0]} watches; standby {watching[1] or 'none'}")

    def _say_guardian_watch(self, guardian: dict[str, Any] | None) -> None:
        """The tick's own watch of the guardian: each loss it counts (it parks the rig; a
        guardian replaced by its standby between two looks counts too, though none is missing)."""
        if guardian is None:
            return
        lost = guardian.get("lost")
        if guardian["losses"] > self._losses:
            self._losses = guardian["losses"]
            self._guardian_lost = lost or "the guardian that watched was replaced by its standby"
            self.say(f"the tick lost its guardian: {self._guardian_lost} (it parks the rig; arming is refused)")

    def _summary(self, now: float) -> str:
        rig = self.rig
        servos = rig.get("servos") or []
        errors = [abs(s["tracking_error_deg"]) for s in servos if s["tracking_error_deg"] is not None]
        temps = [s["temperature_c"] for s in servos if s["temperature_c"] is not None]
        return (
            f"{now - self.start:7.2f} s  {rig['state']:12s} clamps {rig.get('clamps', 0):2d}  "
            f"max tracking error {max(errors, default=0.0):5.2f} deg  max temperature {max(temps, default=0)} C  "
            f"overruns {self.counters.overruns}"
        )


class _SayTransitions(logging.Handler):
    """Each state change the device logs (``devices/lifecycle.py``), said as it happens."""

    def __init__(self, start: float, say: Say) -> None:
        super().__init__(logging.INFO)
        self.start = start
        self.say = say

    def emit(self, record: logging.LogRecord) -> None:
        if record.module != "lifecycle":  # the devices' other messages stay on stderr
            return
        self.say(f"{time.perf_counter() - self.start:7.2f} s  {record.getMessage()}")


def drive_config(rig: RigConfig, rig_file: str, port: str | None, gait: str, guardian: bool) -> ServiceConfig:
    """The service configuration ``rig --drive`` runs: a procedural ``gait`` at the rig's tick
    rate, the rig its one device, a guardian (unless ``guardian`` is False)."""
    return ServiceConfig(
        tick=TickSection(rate=rig.bus.tick_hz),
        source=SourceSection(kind="procedural", gait=gait),
        rig=RigSection(file=rig_file, port=port, rate_policy="refuse"),
        guardian=GuardianSection(enabled=guardian),
    )


def drive(
    rig_file: str,
    port: str | None,
    seconds: float,
    gait: str = "trot",
    *,
    arm: bool = False,
    guardian: bool = True,
    say: Say = print,
) -> int:
    """Connect the rig of ``rig_file`` (on ``port``: None, the map's) and, when ``arm``, drive
    it for ``seconds`` with the service's tick loop in this process (see the module
    docstring); returns the exit status (:class:`Ending`)."""
    rig = load_rig(rig_file)
    config = drive_config(rig, rig_file, port, gait, guardian)
    spec, _ = plan("dynamixel", rig_file, port, config.tick.rate, config.rig.rate_policy)
    layout = RecordLayout((), RIDER_PART_NAMES)  # the service's record without the tail physics
    memory = TickMemory(layout.width, output_capacity=64, handover_blob=False)  # nobody reads the records
    setup = memory.attach(make_setup(config, load_preset(config.tick.preset), layout, (spec,)))
    board = memory.board
    board.tick_pid = board.web_pid = os.getpid()  # the tick and the operator's side: one process
    board.tick_generation = 1
    guardians = None
    if setup.guardian:
        section = config.guardian
        times = GuardianTimes(TICK_TIMEOUT_S + spec.longest_wait_s, section.web_timeout, section.give_up)
        guardians = Guardians(board, memory.latch.name, (spec,), times)
    commands, tick_end = multiprocessing.Pipe(duplex=True)
    notify = os.open(os.devnull, os.O_WRONLY)  # nobody reads the output records
    operator = Operator(memory, commands, DrivePlan(spec, seconds, arm), guardians, say)
    thread = threading.Thread(target=operator.run, name="rig-drive operator", daemon=True)
    transitions = logging.getLogger("riderlive.devices")  # devices/lifecycle.py logs each change there
    handler, kept = _SayTransitions(operator.start, say), transitions.level
    transitions.addHandler(handler)
    transitions.setLevel(logging.INFO)
    try:
        if guardians is not None:
            guardians.start()
            why = _wait_for_guardian(guardians)
            if why is not None:
                say(f"{why}: nothing will move without it (--no-guardian to skip)")
                return EXIT_FAULT
        loop = prepare(setup, tick_end, notify)
        thread.start()
        serve(loop, signals=Signals.OPERATOR)
    finally:
        operator.done.set()
        if thread.ident is not None:
            thread.join()
        if guardians is not None:
            guardians.stop()
        transitions.removeHandler(handler)
        transitions.setLevel(kept)
        commands.close()
        tick_end.close()
        os.close(notify)
        memory.close()
    return _said_ending(operator, say)


def _said_ending(operator: Operator, say: Say) -> int:
    ending = operator.ending or Ending.FAULT
    rig = operator.rig
    if ending is Ending.ESTOP:
        confirmed = bool((rig.get("estop") or {}).get("confirmed"))
        say("e-stopped: torque off" + (" (read back)" if confirmed else " (NOT read back)"))
        return ending.exit_code
    if operator.why:
        say(operator.why)
    fault = rig.get("fault")
    say(f"closed; fault: {fault['message'] if fault else 'none'}")
    return ending.exit_code


def _wait_for_guardian(guardians: Guardians) -> str | None:
    """None once the guardian is ready; else why it is not (exited, or not ready in time)."""
    deadline = time.perf_counter() + GUARDIAN_START_S
    while (why := guardians.ready()) is not None:
        if time.perf_counter() > deadline or guardians.guardian is None or guardians.guardian.poll() is not None:
            return why
        time.sleep(0.02)
    return None


# -- the command ----------------------------------------------------------------------------


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("rig", help="a rig map: a path, or a name in config/rigs")
    parser.add_argument("--port", help="serial port (default: the rig map's)")
    parser.add_argument("--drive", type=float, metavar="SECONDS", help="connect, and drive it for SECONDS when armed")
    parser.add_argument("--arm", action="store_true", help="arm the rig once connected: it moves (soft start first)")
    parser.add_argument("--gait", default="trot", help="walk, trot, canter or gallop (default trot)")
    parser.add_argument("--no-guardian", action="store_true", help="no dead-man process (not near people)")


def describe(rig: RigConfig) -> str:
    """The wire budget and one line per servo."""
    lines = [
        wire_budget(rig),
        f"{'servo':18s} {'id':>3s} {'model':11s} {'channel':14s} {'gain':>7s} {'dir':>3s} "
        f"{'zero':>6s} {'min':>6s} {'max':>6s} {'park':>6s} {'deg/s':>6s}",
    ]
    for name, s in rig.servos.items():
        lines.append(
            f"{name:18s} {s.id:3d} {s.model:11s} {s.channel:14s} {s.gain:7g} {s.direction:3d} "
            f"{s.zero_deg:6.1f} {s.min_deg:6.1f} {s.max_deg:6.1f} {s.park:6.1f} {s.max_speed_dps:6.0f}"
        )
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(message)s")
    try:
        rig = load_rig(args.rig)
    except ConfigError as exc:
        print(f"error: {exc}")
        return 2
    if args.port:
        rig = rig.with_port(args.port)
    print(describe(rig), flush=True)
    if args.drive:
        path = Path(args.rig)
        rig_file = str(path if path.suffix or path.exists() else RIG_DIR / f"{args.rig}.toml")
        return drive(rig_file, args.port, args.drive, args.gait, arm=args.arm, guardian=not args.no_guardian)
    return 0
