"""``riderlive rig``: check a servo map; ``--drive`` it with the service's own tick loop.

    riderlive rig config/rigs/bench3.toml                         # validate, print the map and wire budget
    riderlive rig bench3 --port /dev/ttyUSB0 --drive 30           # connect, check, configure: disarmed, nothing moves
    riderlive rig bench3 --port /dev/ttyUSB0 --drive 30 --arm     # arm: soft start, trot 30 s, park, torque off

``--drive`` runs the tick of ``riderlive serve`` in this process: the same
:class:`~riderlive.realtime.tick.TickLoop` (``realtime/tick_process.serve``), built from the
same setup (``make_setup`` on a service configuration: a procedural horse at the rig's tick
rate, the rig its one device) on its own shared memory
(:class:`~riderlive.realtime.memory.TickMemory`). An operator thread (``riderlive/rig_operator.py``)
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

Exit status (``rig_operator.Ending``): 0 the rig was driven for SECONDS and parked (or, without
``--arm``, connected and left disarmed); 1 a fault, or a stop nobody asked for (the arm
refused, the guardian lost: parked by the tick); 130 an e-stop; 2 a bad map.
"""

from __future__ import annotations

import argparse
import logging
import multiprocessing
import os
import threading
import time
from pathlib import Path

from riderlive.channels import RIDER_PART_NAMES
from riderlive.configfile import ConfigError
from riderlive.devices.guardians import Guardians, GuardianTimes
from riderlive.devices.registry import plan
from riderlive.dynamixel.rig import RIG_DIR, RigConfig, load_rig, wire_budget
from riderlive.realtime.memory import TickMemory
from riderlive.realtime.record import RecordLayout
from riderlive.realtime.tick_process import Signals, prepare, serve
from riderlive.rig_operator import EXIT_FAULT, DrivePlan, Operator, Say, said_ending
from riderlive.rules.params import load_preset
from riderlive.service.config import GuardianSection, RigSection, ServiceConfig, SourceSection, TickSection
from riderlive.service.tick_setup import make_setup

TICK_TIMEOUT_S = 0.1
"""The guardian's hung-tick threshold for ``rig --drive`` (s), plus the rig's longest
legitimate wait: no supervisor watches this tick (``serve``'s kills a hung tick in 30 ms at
real-time priority), so the guardian's own threshold is the short one."""
GUARDIAN_START_S = 15.0
"""How long the guardian may take to start (its imports on a loaded host) before the drive gives up."""


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
        times = GuardianTimes(
            TICK_TIMEOUT_S + spec.longest_wait_s, section.web_timeout, section.give_up, section.priority
        )
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
    return said_ending(operator, say)


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
