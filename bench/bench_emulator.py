"""Round trip of one bus tick (Sync Write of goals + Fast Sync Read of positions) on the emulator.

    PYTHONPATH=$PWD .venv/bin/python bench/bench_emulator.py [--servos 24] [--ticks 400]

The emulator runs in its own process (``riderlive servo-emu``), as it would next to the
service, so it does not share the GIL with the SDK. For each baud, with and without wire
timing, prints the tick time (p50/p99) and the ratio of the theoretical wire time
(bytes x 10 / baud, Return Delay Time 0) to the measured p50: 1.0 means the loop runs
as fast as the wire allows; without wire timing it shows the software overhead alone.

Baseline, measured in the same run: the same SDK loop against a bare responder process
that answers each Fast Sync Read with a canned reply (no register memory, no model):
the floor of SDK + pty + process wake-ups on this machine at this moment. "emu CPU" is
the emulator thread's CPU time per tick (ms) handling packets: unlike the wall-clock
figures it hardly depends on what else the machine is running.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import select
import signal
import statistics
import subprocess
import sys
import time
import tty
from pathlib import Path

from dynamixel_sdk import COMM_SUCCESS, GroupSyncRead, GroupSyncWrite, PacketHandler, PortHandler

from riderlive.dynamixel.emulator.protocol import PacketReader, encode_fast_status

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


def start_baseline(n: int) -> tuple[subprocess.Popen[str], str, int]:
    """A bare responder on a fresh pty: canned Fast Sync Read replies, nothing else."""
    master, slave = os.openpty()
    tty.setraw(slave)
    entries = [(i, 0, (2048).to_bytes(4, "little")) for i in range(1, n + 1)]
    reply = encode_fast_status(entries).hex()
    cmd = [sys.executable, __file__, "--respond", str(master), reply]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(cmd, pass_fds=[master], env=env, text=True)
    os.close(master)
    return proc, os.ttyname(slave), slave


def respond(master: int, reply: bytes) -> None:
    """The baseline responder's loop: a Fast Sync Read request in, the canned reply out."""
    reader = PacketReader()
    while True:
        select.select([master], [], [])
        try:
            reader.feed(os.read(master, 4096))
        except OSError:
            return
        for packet in reader.packets():
            if isinstance(packet, bytes) and packet[7] == 0x8A:
                os.write(master, reply)


def measure(port_path: str, n: int, baud: int, ticks: int, setup: bool = True) -> list[float]:
    port = PortHandler(port_path)
    assert port.openPort() and port.setBaudRate(baud)
    ph = PacketHandler(2.0)
    ids = range(1, n + 1)
    if setup:  # Return Delay Time 0 (as the rig configures it), torque on
        delays = GroupSyncWrite(port, ph, RETURN_DELAY, 1)
        for i in ids:
            delays.addParam(i, [0])
        assert delays.txPacket() == COMM_SUCCESS
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
    parser.add_argument("--respond", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.respond:
        respond(int(args.respond[0]), bytes.fromhex(args.respond[1]))
        return 0
    n = args.servos
    print(f"{n} servos, one tick = Sync Write (goals) + Fast Sync Read (present position), {args.ticks} ticks")
    print(
        f"{'baud':>9} {'wire timing':>11} {'theory ms':>9} {'p50 ms':>7} {'p99 ms':>7} {'ticks/s':>8} {'wire/p50':>8}"
    )
    proc, port_path, slave = start_baseline(n)
    try:
        floor = statistics.median(measure(port_path, n, 1_000_000, args.ticks, setup=False))
    finally:
        proc.kill()
        proc.wait()
        os.close(slave)
    print(f"baseline (bare responder, no wire timing): p50 {floor * 1e3:.2f} ms")
    for baud in (1_000_000, 4_000_000):
        theory = wire_bytes(n) * 10 / baud
        for wire_timing in (False, True):
            proc, port_path = start_emulator(n, baud, wire_timing)
            try:
                times = measure(port_path, n, baud, args.ticks)
            finally:
                proc.send_signal(signal.SIGINT)
                out, _ = proc.communicate(timeout=10)
            found = re.search(r"([0-9.]+) s CPU handling", out)
            cpu = float(found.group(1)) / (len(times) + 20) if found else math.nan
            p50 = statistics.median(times)
            p99 = sorted(times)[int(0.99 * (len(times) - 1))]
            print(
                f"{baud:>9} {'on' if wire_timing else 'off':>11} {theory * 1e3:>9.2f} {p50 * 1e3:>7.2f} "
                f"{p99 * 1e3:>7.2f} {1 / p50:>8.0f} {theory / p50:>8.2f} {floor / p50:>8.2f} {cpu * 1e3:>8.2f}"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
