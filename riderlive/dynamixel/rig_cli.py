"""``riderlive rig``: check a servo map, and drive it with a procedural horse.

    riderlive rig config/rigs/bench3.toml                         # validate, print the map and wire budget
    riderlive rig bench3 --port /dev/ttyUSB0 --drive 30           # connect, check, configure: disarmed, nothing moves
    riderlive rig bench3 --port /dev/ttyUSB0 --drive 30 --arm     # arm: soft start, trot 30 s, park, torque off

Driving runs the device lifecycle (connecting -> disarmed -> soft_start -> running ->
parking -> parked) at the rig's tick rate and prints the status once a second, with a
guardian process that parks the rig if this process is killed. Nothing moves without
``--arm``. Ctrl-C (SIGINT) or SIGTERM is an e-stop: torque off at once (category 0),
read back until every servo confirms, then exit.
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import subprocess
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from riderlive.configfile import ConfigError
from riderlive.dynamixel.rig import RigConfig, load_rig, wire_budget

if TYPE_CHECKING:
    from riderlive.devices.board import SafetyBoard

log = logging.getLogger("riderlive.dynamixel")
EXIT_FAULT, EXIT_ESTOP = 1, 130


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("rig", help="a rig map: a path, or a name in config/rigs")
    parser.add_argument("--port", help="serial port (default: the rig map's)")
    parser.add_argument("--drive", type=float, metavar="SECONDS", help="connect, and drive it for SECONDS when armed")
    parser.add_argument("--arm", action="store_true", help="arm the rig once connected: it moves (soft start first)")
    parser.add_argument("--gait", default="trot", help="walk, trot, canter or gallop (default trot)")
    parser.add_argument("--no-guardian", action="store_true", help="no dead-man process (not near people)")


def describe(rig: RigConfig) -> str:
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


def drive(rig: RigConfig, seconds: float, gait: str, arm: bool = False, rig_file: str | None = None) -> int:
    """Connect and (when ``arm``) drive the rig; with ``rig_file`` a guardian watches.
    Returns 0, ``EXIT_FAULT`` after a fault, ``EXIT_ESTOP`` after an e-stop."""
    from riderlive.devices.board import SafetyBoard
    from riderlive.devices.guardian import launch
    from riderlive.devices.latch import StopLatch, StopSource
    from riderlive.devices.lifecycle import DeviceState as S
    from riderlive.devices.lifecycle import Refused
    from riderlive.devices.registry import DeviceSpec
    from riderlive.dynamixel.driver import rig_device
    from riderlive.horse import DEFAULT_SCALE, ProceduralHorse
    from riderlive.realtime.pacing import DeadlineClock
    from riderlive.rules import RiderModel
    from riderlive.tickframe import Flag, TickFrame

    horse, model = ProceduralHorse(gait), RiderModel(scale=DEFAULT_SCALE)
    latch, board = StopLatch(), SafetyBoard()
    board.tick_pid, board.tick_generation = os.getpid(), 1
    guardian = None
    if rig_file is not None:
        spec = DeviceSpec("dynamixel", rig_file, rig.bus.port, rig.name, 1, rig.bus.tick_s)
        guardian = launch(board.name, latch.name, [spec], tick_timeout_s=0.1, web_timeout_s=1.0)
    device = rig_device(rig, latch=latch)
    wake_read, wake_write = os.pipe()
    os.set_blocking(wake_read, False)
    os.set_blocking(wake_write, False)
    previous_fd = signal.set_wakeup_fd(wake_write, warn_on_full_buffer=False)
    handlers = {sig: signal.signal(sig, lambda *_: latch.request(StopSource.SIGNAL)) for sig in (2, 15)}
    say: Callable[[str], None] = print
    start = time.perf_counter()
    armed = parked_asked = estopped = False
    try:
        _wait_for_guardian(board, guardian)
        device.connect("cli")
        clock = DeadlineClock(rig.bus.tick_s, start=start)
        next_print = start + 1.0
        while True:
            woke = clock.wait_or_wake([wake_read], lambda: device.stops.pending)
            now = time.perf_counter()
            board.tick_beat = now
            if woke is None:
                _drain(wake_read)
                device.poll_stop(now)
            rider = model.evaluate(horse.sample(now - start))  # the horse in metres: the rider too
            frame = TickFrame.build(clock.tick, now - start, now, now - start, Flag.PROCEDURAL, rider)
            status = device.tick(frame, now)
            board.publish(0, device.state, device.plug.pose)
            for t in status.transitions:
                say(f"{now - start:7.2f} s  {t.source.value} -> {t.target.value}: {t.reason} (by {t.by})")
            state = device.state
            if state is S.ESTOP:
                estopped = True
                if status.outputs_off_confirmed or now - start > seconds + 5.0:
                    break
            elif state is S.FAULT:
                break
            elif state is S.DISARMED and not armed:
                if not arm:
                    say("disarmed: connected, checked, configured, torque off. Nothing moves without --arm.")
                    break
                armed = True
                try:
                    device.arm(device.name, "cli --arm")
                except Refused as exc:
                    say(f"not armed: {exc}")
                    break
            elif state is S.PARKED:
                break
            if armed and not parked_asked and now - start >= seconds:
                parked_asked = True
                device.disarm("cli: time is up")
            if now >= next_print:
                next_print += 1.0
                say(_summary(status.to_dict(), now - start, clock.overruns))
    finally:
        device.close("cli")
        board.tick_clean_exit, board.shutdown = 1, 1.0
        if guardian is not None:
            guardian.wait(5.0)
        signal.set_wakeup_fd(previous_fd)
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
        os.close(wake_read)
        os.close(wake_write)
        latch.close()
        board.close()
    fault = device.fault
    if estopped:
        say("e-stopped: torque off" + (" (read back)" if device.last_stop and device.last_stop.confirmed_at else ""))
        return EXIT_ESTOP
    say(f"closed; fault: {fault.message if fault else 'none'}")
    return EXIT_FAULT if fault else 0


def _wait_for_guardian(board: SafetyBoard, guardian: subprocess.Popen[bytes] | None) -> None:
    if guardian is None:
        return
    deadline = time.perf_counter() + 15.0
    while board.guardian_ready != 1.0:
        if time.perf_counter() > deadline or guardian.poll() is not None:
            raise RuntimeError("the guardian did not start: nothing will move without it (--no-guardian to skip)")
        time.sleep(0.02)


def _drain(fd: int) -> None:
    try:
        while os.read(fd, 4096):
            pass
    except (BlockingIOError, OSError):
        pass


def _summary(status: dict[str, Any], t: float, overruns: int) -> str:
    servos = status.get("servos") or []
    errors = [abs(s["tracking_error_deg"]) for s in servos if s["tracking_error_deg"] is not None]
    temps = [s["temperature_c"] for s in servos if s["temperature_c"] is not None]
    return (
        f"{t:7.2f} s  {status['state']:12s} clamps {status.get('clamps', 0):2d}  "
        f"max tracking error {max(errors, default=0.0):5.2f} deg  max temperature {max(temps, default=0)} C  "
        f"overruns {overruns}"
    )


def run(args: argparse.Namespace) -> int:
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(message)s")
    try:
        rig = load_rig(args.rig)
    except ConfigError as exc:
        print(f"error: {exc}")
        return 2
    if args.port:
        rig = rig.with_port(args.port)
    print(describe(rig))
    if args.drive:
        rig_file = None if args.no_guardian else _rig_path(args.rig)
        return drive(rig, args.drive, args.gait, arm=args.arm, rig_file=rig_file)
    return 0


def _rig_path(name: str) -> str:
    from pathlib import Path

    from riderlive.dynamixel.rig import RIG_DIR

    path = Path(name)
    return str(path if path.suffix or path.exists() else RIG_DIR / f"{name}.toml")
