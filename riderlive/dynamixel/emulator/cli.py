"""``riderlive servo-emu``: run an emulated Dynamixel bus on a pseudo-terminal.

    riderlive servo-emu --rig config/rigs/bench3.toml --link /tmp/riderlive-bus
    riderlive servo-emu --servo 1:XL430-W250 --servo 2:XM430-W350 --wire-timing
    riderlive servo-emu --rig config/rigs/full_rider.toml --fault vanish:7@10 --fault close@20

Prints the pty path (``port: /dev/pts/N``) as its first line; point the SDK or the rig's
``bus.port`` at it (or at the ``--link`` symlink). Stops on Ctrl-C, after
``--duration``, or when a ``close`` fault fires; prints what it saw.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import time
from pathlib import Path
from typing import Any

from riderlive.dynamixel.emulator.bus import DEFAULT_BAUD, EmulatedBus
from riderlive.dynamixel.emulator.faults import FaultSpec, parse_fault
from riderlive.dynamixel.emulator.servo import ServoSetup
from riderlive.dynamixel.models import model_spec
from riderlive.dynamixel.tables import PULSES_PER_TURN
from riderlive.sched import try_realtime_priority


def parse_servo(text: str) -> ServoSetup:
    """``ID:MODEL[:POSITION]`` -> a servo setup (position in pulses, default 2048)."""
    parts = text.split(":")
    try:
        if len(parts) not in (2, 3):
            raise ValueError
        servo_id = int(parts[0])
        position = int(parts[2]) if len(parts) == 3 else 2048
    except ValueError:
        raise argparse.ArgumentTypeError(f"bad servo {text!r}: expected ID:MODEL[:POSITION]") from None
    try:
        model_spec(parts[1].upper())
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    if not 0 <= servo_id <= 252:
        raise argparse.ArgumentTypeError(f"bad servo {text!r}: id must be within 0..252")
    return ServoSetup(servo_id, parts[1].upper(), position)


def _fault(text: str) -> FaultSpec:
    try:
        return parse_fault(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def servos_from_rig(path: str) -> tuple[list[ServoSetup], int]:
    """The servos (each starting at its park pose) and baud of a rig file."""
    rig_module: Any = importlib.import_module("riderlive.dynamixel.rig")
    rig = rig_module.load_rig(path)
    setups = [
        ServoSetup(servo.id, servo.model, round(servo.park / 360.0 * PULSES_PER_TURN) % PULSES_PER_TURN)
        for servo in rig.servos.values()
    ]
    return setups, int(rig.bus.baud)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--rig", help="rig file (config/rigs/NAME.toml): its servos and baud")
    parser.add_argument(
        "--servo", action="append", type=parse_servo, default=[], metavar="ID:MODEL[:POS]", help="add a servo"
    )
    parser.add_argument("--baud", type=int, help=f"bus speed in bit/s (default: the rig's, else {DEFAULT_BAUD})")
    parser.add_argument("--wire-timing", action="store_true", help="hold every packet for bytes x 10 / baud")
    parser.add_argument("--reboot-time", type=float, default=0.0, help="seconds a servo stays deaf after REBOOT")
    parser.add_argument(
        "--fault", action="append", type=_fault, default=[], metavar="SPEC", help="e.g. drop:3:5, vanish:7@10, close@20"
    )
    parser.add_argument("--link", help="also make this path a symlink to the pty (replaced if it is a symlink)")
    parser.add_argument(
        "--duration", type=float, default=0.0, help="stop after this many seconds (0: run until Ctrl-C)"
    )
    parser.add_argument(
        "--realtime",
        type=int,
        default=0,
        metavar="PRIORITY",
        help="run at SCHED_FIFO PRIORITY where allowed, as servos a busy host cannot starve (0: normal)",
    )


def run(args: argparse.Namespace) -> int:
    servos: list[ServoSetup] = []
    baud = args.baud
    if args.rig:
        try:
            rig_servos, rig_baud = servos_from_rig(args.rig)
        except (ValueError, OSError, ImportError) as exc:
            print(f"servo-emu: {exc}", file=sys.stderr)
            return 2
        servos += rig_servos
        baud = baud or rig_baud
    servos += args.servo
    if not servos:
        print("servo-emu: no servos: give --rig and/or --servo ID:MODEL", file=sys.stderr)
        return 2
    try:
        bus = EmulatedBus(
            servos, baud=baud or DEFAULT_BAUD, wire_timing=args.wire_timing, reboot_time_s=args.reboot_time
        )
    except ValueError as exc:
        print(f"servo-emu: {exc}", file=sys.stderr)
        return 2
    stop = False

    def on_signal(signum: int, frame: object) -> None:
        nonlocal stop
        stop = True

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    if args.realtime:  # before the bus's thread starts: it inherits the policy
        try_realtime_priority(args.realtime, who="the emulated servos")
    with bus:
        if args.link:
            link = Path(args.link)
            if link.is_symlink():
                link.unlink()
            os.symlink(bus.port, link)
        ids = ", ".join(f"{s.id}:{s.spec.model.value}" for s in bus.servos)
        print(f"port: {bus.port}", flush=True)
        print(f"servo-emu: {len(bus.servos)} servos ({ids}) at {bus.baud} bit/s", flush=True)
        pending = sorted(args.fault, key=lambda f: f.at_s)
        start = time.monotonic()
        while not stop and not bus.closed:
            elapsed = time.monotonic() - start
            while pending and pending[0].at_s <= elapsed:
                fault = pending.pop(0)
                print(f"servo-emu: {elapsed:.3f} s: {fault.kind.value} {fault.servo_id or ''}".rstrip(), flush=True)
                bus.apply(fault)
            if args.duration and elapsed >= args.duration:
                break
            time.sleep(0.01)
        stats = bus.stats
        if args.link and Path(args.link).is_symlink():
            Path(args.link).unlink()
    print(
        f"servo-emu: {stats.packets} packets, {stats.replies} replies, {stats.crc_errors} CRC errors, "
        f"{stats.dropped_replies} dropped, {stats.corrupted_replies} corrupted, "
        f"{stats.handling_cpu_s:.3f} s CPU handling; {dict(stats.instructions)}",
        flush=True,
    )
    return 0
