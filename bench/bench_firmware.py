"""firmware_proto: parser throughput, dead-man latency on the pty, fuzzing, the cross build's size.

    .venv/bin/python bench/bench_firmware.py                     # parser, dead-man (20 trials), size
    .venv/bin/python bench/bench_firmware.py --fuzz-runs 10000000  # + 10^7 fuzzed inputs (~8 min)

Parser: ``make bench`` (C, -O2): MB/s of mixed valid and corrupt traffic through
``link_rx_byte`` and ``device_receive``, against a baseline loop in the same run that only
splits the bytes at 0x00; then the undetected rate of 10^6 corrupted frames.

Size and speed on the MCU: ``make cross`` (flash, static RAM) and ``make avr-step-bench``
(the cost of one control period on the ATmega2560 in simavr, when simavr is installed).

Slowest park: the host build at each profile's CONFIG floors, parked by the dead-man from
the far soft limit: first park step to outputs off, against the 5 s bound.

Dead-man: the host build on a pty, servo8 profile; each trial arms, streams targets until
RUNNING, then stops sending. The firmware prints the CLOCK_MONOTONIC time of its last valid
frame and of its first park step; Python's last write is on the same clock. Bound: heartbeat
timeout (200 ms) + one control period (4 ms). Baseline in the same run: the pty round trip
(RESET -> STATUS) that adds to the Python-side figure.
"""

from __future__ import annotations

import argparse
import re
import shutil
import statistics
import subprocess
import sys
import time

from riderlive.platform.firmware_host import FIRMWARE_DIR, FirmwareHost
from riderlive.platform.link import Arm, Config, Heartbeat, Reset, Target
from riderlive.platform.link_vocab import (
    CONFIG_RANGES,
    PARK_BOUND_S,
    ConfigKey,
    Fault,
    LinkState,
    Profile,
    firmware_park_s,
)
from riderlive.platform.serial_link import SerialPlatformLink


def make(*targets: str) -> str:
    result = subprocess.run(
        ["make", "--no-print-directory", "-C", str(FIRMWARE_DIR), *targets], capture_output=True, text=True, check=True
    )
    return result.stdout + result.stderr


def deadman(trials: int) -> None:
    firmware_side, python_side, round_trips = [], [], []
    with FirmwareHost("servo8") as firmware, SerialPlatformLink(firmware.port, heartbeat_s=10.0) as port:
        port.open()
        for _ in range(trials):
            start = time.monotonic()
            port.command(Reset())  # a round trip: RESET -> STATUS (from fault, or a no-op)
            round_trips.append((time.monotonic() - start) * 1e3)
            port.command(Arm("servo8"))
            k = 0
            while port.telemetry is None or LinkState(port.telemetry.state) is not LinkState.RUNNING:
                port.send(Target((3000,) * 8))
                port.service()
                k += 1
                time.sleep(0.004)
            mark = len(firmware.events)
            port.send(Target((3000,) * 8))  # the last valid frame
            last_write_ns = time.monotonic_ns()
            park = firmware.wait_event(lambda e: e["event"] == "park_step", 2.0, mark)
            firmware_side.append((park["t_ns"] - park["last_rx_t_ns"]) / 1e6)
            python_side.append((park["t_ns"] - last_write_ns) / 1e6)
            port.wait_telemetry(lambda t: LinkState(t.state) is LinkState.FAULT, 3.0)
    bound = 200 + 4
    for name, values in (("firmware clock", firmware_side), ("from Python's last write", python_side)):
        print(
            f"dead-man, last valid frame -> first park step ({name}): median {statistics.median(values):.1f} ms, "
            f"min {min(values):.1f}, max {max(values):.1f}, bound {bound} ms, "
            f"over the bound {sum(v > bound for v in values)}/{len(values)}"
        )
    print(f"baseline: RESET -> STATUS round trip on the pty: median {statistics.median(round_trips):.2f} ms")


def slowest_park(profile: str, far: int) -> None:
    """The host build (real time, simulated actuators) at its CONFIG floors: the dead-man park
    from the far limit, first park step -> outputs off (fault), against link_vocab.PARK_BOUND_S."""
    ranges = CONFIG_RANGES[Profile[profile.upper()]]
    v, a = ranges[ConfigKey.VELOCITY_LIMIT][0], ranges[ConfigKey.ACCELERATION_LIMIT][0]
    with FirmwareHost(profile) as firmware, SerialPlatformLink(firmware.port, heartbeat_s=10.0) as port:
        hello = port.open()
        for i in range(hello.actuators):
            port.command(Config(ConfigKey.VELOCITY_LIMIT, i, v))
            port.command(Config(ConfigKey.ACCELERATION_LIMIT, i, a))
        port.command(Arm(profile))
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline:  # homing (platforms), soft start, then at the far limit
            t = port.telemetry
            if t is not None and LinkState(t.state) is LinkState.HOMING:
                port.send(Heartbeat())
            else:
                port.send(Target((far,) * hello.actuators))
            port.service()
            if (
                t is not None
                and LinkState(t.state) is LinkState.RUNNING
                and all(abs(c - far) <= 5 for c in t.commanded)
            ):
                break
            time.sleep(0.004)
        mark = len(firmware.events)
        park = firmware.wait_event(lambda e: e["event"] == "park_step", 2.0, mark)
        off = firmware.wait_event(lambda e: e["event"] == "state" and e["to"] == "fault", 30.0, mark)
    seconds = (off["t_ns"] - park["t_ns"]) / 1e9
    cut = "cut at the bound by PARK_TIMEOUT (a starved loop)" if off["faults"] & Fault.PARK_TIMEOUT else "parked"
    print(
        f"slowest park, {profile} at its CONFIG floors ({v} counts/s, {a} counts/s^2), host build on the pty, "
        f"from {far} counts: first park step -> outputs off {seconds:.2f} s, {cut} (bound {PARK_BOUND_S:g} s; "
        f"formula {firmware_park_s(abs(far - (500 if profile != 'servo8' else 0)), v, a):.2f} s from full speed)"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--megabytes", type=int, default=32)
    parser.add_argument("--fuzz-runs", type=int, default=0, help="run `make fuzz` with this many inputs")
    args = parser.parse_args()
    out = make("bench", f"BENCH_ARGS={args.megabytes} 1000000")
    print(out.strip())
    deadman(args.trials)
    slowest_park("servo8", 8500)
    slowest_park("platform6", 14500)
    sizes = re.findall(r"^.*flash.*$", make("cross"), re.M)
    print("\n".join(sizes))
    if shutil.which("simavr"):
        out = re.sub(r"\x1b\[[0-9;]*m", "", make("avr-step-bench"))
        print("\n".join(re.findall(r"^avr (?:crc16|control).*$", out, re.M)))
    if args.fuzz_runs:
        start = time.monotonic()
        out = make("fuzz", f"FUZZ_RUNS={args.fuzz_runs}")
        done = re.findall(r"Done \d+ runs in \d+ second\(s\)|fuzz_stream: .*", out)
        print(f"fuzz: {done[-1] if done else out[-500:]} ({time.monotonic() - start:.0f} s wall)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
