"""Round trip of one bus tick (Sync Write of goals + Fast Sync Read of positions) on the emulator.

    PYTHONPATH=$PWD .venv/bin/python bench/bench_emulator.py [--servos 24] [--ticks 400]

The emulator runs in its own process (``riderlive servo-emu``), as it would next to the
service, so it does not share the GIL with the SDK. For each baud, with and without wire
timing, prints the tick time (p50/p99) and the ratio of the theoretical wire time
(bytes x 10 / baud, Return Delay Time 0) to the measured p50: 1.0 means the loop runs
as fast as the wire allows; without wire timing it shows the software overhead alone.
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

from dynamixel_sdk import COMM_SUCCESS, GroupSyncRead, GroupSyncWrite, PacketHandler, PortHandler

REPO = Path(__file__).resolve().parents[1]
MODELS = ("XM430-W350", "XL430-W250", "XL330-M288")
GOAL, PRESENT, RETURN_DELAY, TORQUE = 116, 132, 9, 64


def wire_bytes(n: int) -> int:
    """Sync Write of 4-byte goals + Fast Sync Read request + its reply."""
    return (14 + 5 * n) + (14 + n) + (8 + 8 * n)


def start_emulator(n: int, baud: int, wire_timing: bool) -> tuple[subprocess.Popen[str], str]:
    cmd = [sys.executable, "-m", "riderlive", "servo-emu", "--baud", str(baud)]
    for i in range(1, n + 1):
        cmd += ["--servo", f"{i}:{MODELS[(i - 1) % len(MODELS)]}"]
    if wire_timing:
        cmd.append("--wire-timing")
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, env=env)
    assert proc.stdout is not None
    line = proc.stdout.readline()
    if not line.startswith("port: "):
        proc.kill()
        raise RuntimeError(f"servo-emu did not start: {line!r}")
    return proc, line.split(": ", 1)[1].strip()


def measure(port_path: str, n: int, baud: int, ticks: int) -> list[float]:
    port = PortHandler(port_path)
    assert port.openPort() and port.setBaudRate(baud)
    ph = PacketHandler(2.0)
    ids = range(1, n + 1)
    setup = GroupSyncWrite(port, ph, RETURN_DELAY, 1)
    for i in ids:
        setup.addParam(i, [0])
    assert setup.txPacket() == COMM_SUCCESS
    assert ph.write1ByteTxRx(port, 0xFE, TORQUE, 1)[0] == COMM_SUCCESS
    writer = GroupSyncWrite(port, ph, GOAL, 4)
    reader = GroupSyncRead(port, ph, PRESENT, 4)
    for i in ids:
        writer.addParam(i, list((2048).to_bytes(4, "little")))
        reader.addParam(i)
    times, failures = [], 0
    for k in range(ticks + 20):
        for i in ids:
            writer.changeParam(i, list((2048 + (k % 200)).to_bytes(4, "little")))
        start = time.perf_counter()
        ok = writer.txPacket() == COMM_SUCCESS and reader.fastSyncRead() == COMM_SUCCESS
        elapsed = time.perf_counter() - start
        failures += not ok
        if k >= 20:  # warm-up
            times.append(elapsed)
    port.closePort()
    if failures:
        print(f"  ({failures} failed ticks)")
    return times


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--servos", type=int, default=24)
    parser.add_argument("--ticks", type=int, default=400)
    args = parser.parse_args()
    n = args.servos
    print(f"{n} servos, one tick = Sync Write (goals) + Fast Sync Read (present position), {args.ticks} ticks")
    print(
        f"{'baud':>9} {'wire timing':>11} {'theory ms':>9} {'p50 ms':>7} {'p99 ms':>7} {'ticks/s':>8} {'wire/p50':>8}"
    )
    for baud in (1_000_000, 4_000_000):
        theory = wire_bytes(n) * 10 / baud
        for wire_timing in (False, True):
            proc, port_path = start_emulator(n, baud, wire_timing)
            try:
                times = measure(port_path, n, baud, args.ticks)
            finally:
                proc.send_signal(signal.SIGINT)
                proc.communicate(timeout=10)
            p50 = statistics.median(times)
            p99 = sorted(times)[int(0.99 * (len(times) - 1))]
            print(
                f"{baud:>9} {'on' if wire_timing else 'off':>11} {theory * 1e3:>9.2f} {p50 * 1e3:>7.2f} "
                f"{p99 * 1e3:>7.2f} {1 / p50:>8.0f} {theory / p50:>8.2f}"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
