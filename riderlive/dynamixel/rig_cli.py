"""``riderlive rig``: check a servo map, and optionally drive it with a procedural horse.

    riderlive rig config/rigs/bench3.toml                       # validate, print the map and wire budget
    riderlive rig bench3 --port /dev/ttyUSB0 --drive 30         # trot for 30 s, then park and torque off
    riderlive rig full_rider --port /tmp/riderlive-bus --drive 10 --gait walk

Driving runs the real lifecycle (check, configure, soft start, run, park, torque off)
at the rig's tick rate and prints the rig status once a second. Ctrl-C parks.
"""

from __future__ import annotations

import argparse
import logging
import time

from riderlive.configfile import ConfigError
from riderlive.dynamixel.rig import MAX_WIRE_SHARE, RigConfig, load_rig, read_tick_seconds, wire_seconds_per_tick


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("rig", help="a rig map: a path, or a name in config/rigs")
    parser.add_argument("--port", help="serial port (default: the rig map's)")
    parser.add_argument("--drive", type=float, metavar="SECONDS", help="drive the rig with a procedural horse")
    parser.add_argument("--gait", default="trot", help="walk, trot, canter or gallop (default trot)")


def describe(rig: RigConfig) -> str:
    bus = rig.bus
    wire = wire_seconds_per_tick(rig)
    lines = [
        f"{rig.name}: {len(rig.servos)} servos on {bus.port} at {bus.baud} baud, {bus.tick_hz:g} ticks/s, "
        f"read every {bus.read_divider} ticks",
        f"wire per tick {wire * 1000:.2f} ms = {wire * bus.tick_hz:.0%} of a tick "
        f"(at most {MAX_WIRE_SHARE:.0%}; the wire allows {1 / wire:.0f} ticks/s)",
        f"a tick with a read takes {read_tick_seconds(rig) * 1000:.2f} ms (at most one tick, "
        f"{bus.tick_s * 1000:.2f} ms)",
        f"{'servo':18s} {'id':>3s} {'model':11s} {'channel':14s} {'gain':>7s} {'dir':>3s} "
        f"{'zero':>6s} {'min':>6s} {'max':>6s} {'park':>6s} {'deg/s':>6s}",
    ]
    for name, s in rig.servos.items():
        lines.append(
            f"{name:18s} {s.id:3d} {s.model:11s} {s.channel:14s} {s.gain:7g} {s.direction:3d} "
            f"{s.zero_deg:6.1f} {s.min_deg:6.1f} {s.max_deg:6.1f} {s.park:6.1f} {s.max_speed_dps:6.0f}"
        )
    return "\n".join(lines)


def drive(rig: RigConfig, seconds: float, gait: str) -> int:
    from riderlive.dynamixel.driver import RigDriver
    from riderlive.dynamixel.lifecycle import RigState
    from riderlive.horse import DEFAULT_SCALE, ProceduralHorse
    from riderlive.rules import RiderModel

    horse, model = ProceduralHorse(gait), RiderModel(scale=DEFAULT_SCALE)
    driver = RigDriver(rig)
    driver.open()
    start = next_tick = next_print = time.perf_counter()
    overruns = 0
    try:
        while (now := time.perf_counter()) - start < seconds:
            status = driver.tick(model.evaluate(horse.sample(now - start)), now)
            for transition in status.transitions:
                print(
                    f"{now - start:7.2f} s  {transition.source.value} -> {transition.target.value}: {transition.reason}"
                )
            if status.state in (RigState.FAULT, RigState.ESTOP):
                break
            if now >= next_print:
                next_print += 1.0
                errors = [abs(e) for e in status.tracking_error_deg if e is not None]
                temps = [t for t in status.temperature_c if t is not None]
                print(
                    f"{now - start:7.2f} s  {status.state.value:10s} clamps {sum(status.clamped):2d}  "
                    f"max tracking error {max(errors, default=0.0):5.2f} deg  "
                    f"max temperature {max(temps, default=0)} C  overruns {overruns}"
                )
            next_tick += rig.bus.tick_s
            late = time.perf_counter() - next_tick
            if late > 0:
                overruns += 1
                next_tick = time.perf_counter()
            else:
                time.sleep(-late)
    except KeyboardInterrupt:
        print("interrupted: parking")
    driver.close()
    print(f"closed; fault: {driver.fault.message if driver.fault else 'none'}")
    return 0 if driver.fault is None else 1


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
        return drive(rig, args.drive, args.gait)
    return 0
