"""The rig driver on a 24-servo emulated bus with wire timing: loop rate and e-stop latency.

    PYTHONPATH=$PWD .venv/bin/python bench/bench_bus.py [--seconds 3] [--trials 8] [--bauds 1000000 4000000]

The emulator runs in a child process (so the SDK's busy-polling reads do not share a
GIL with it) and holds every packet on the wire for bytes x 10 / baud.

Loop rate: the driver in RUNNING, unpaced, one goal SYNC_WRITE per tick and a Fast
Sync Read of 15 bytes (present position .. temperature) every ``read_divider`` ticks.
Reported against two baselines from the same run:

- the rate the wire allows: baud / 10 / (bytes per tick, the divided read included);
  target ratio >= 0.8 (issue 5);
- the bare SDK doing the same transactions in a tight loop (the driver's overhead).

E-stop: the driver paced at the rig's tick rate; another thread calls ``estop()`` at a
random moment; latency = estop() call to the torque-off SYNC_WRITE having fully
arrived at the emulator. Target <= one tick + 1 ms.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import random
import statistics
import sys
import threading
import time
from multiprocessing.connection import Connection
from typing import Any

import dynamixel_sdk as sdk
from riderlive.dynamixel.lifecycle import RigState

from riderlive.channels import RIDER
from riderlive.dynamixel.driver import RigDriver
from riderlive.dynamixel.rig import READ_BYTES, RigConfig, load_rig, wire_bytes_per_tick
from riderlive.dynamixel.sdkbus import RigPort
from riderlive.horse import DEFAULT_SCALE, ProceduralHorse
from riderlive.rules import RiderModel
from tests.dynamixel.rig_harness import TimedBus, servo_setups


def _serve(conn: Connection, rig: RigConfig, baud: int, wire_timing: bool) -> None:
    """Child process: the emulator; answers 'settle', 'torque_off_at', 'stop'."""
    bus = TimedBus(servo_setups(rig), baud=baud, wire_timing=wire_timing).start()
    conn.send(bus.port)
    while True:
        command = conn.recv()
        if command == "settle":
            bus.settle(timeout=30.0)
            conn.send(dict(bus.stats.instructions))
        elif command == "torque_off_at":
            bus.settle()
            conn.send(bus.torque_off_at)
            bus.torque_off_at = None
        elif command == "stop":
            bus.stop()
            conn.send(None)
            return


def trot_frames(count: int, hz: float) -> list[list[float]]:
    horse, model = ProceduralHorse("trot"), RiderModel(scale=DEFAULT_SCALE)
    return [model.evaluate(horse.sample(i / hz)) for i in range(count)]


def start(driver: RigDriver, frames: list[list[float]], timeout: float = 60.0) -> None:
    if driver.state is RigState.CLOSED:
        driver.open()
    else:
        driver.reset()
    deadline = time.perf_counter() + timeout
    i = 0
    while driver.state is not RigState.RUNNING and time.perf_counter() < deadline:
        driver.tick(frames[i % len(frames)], time.perf_counter())
        i += 1
        time.sleep(driver.config.bus.tick_s)
    if driver.state is not RigState.RUNNING:
        raise SystemExit(f"the rig did not start: {driver.state.value}, {driver.fault}")
    print(f"  (started in {time.perf_counter() - deadline + timeout:.1f} s, {i} ticks)")


def driver_rate(
    driver: RigDriver, frames: list[list[float]], seconds: float, repeats: int
) -> tuple[float, float, dict[str, int]]:
    """Ticks per second, unpaced, while RUNNING (best of ``repeats`` windows: the machine
    is shared); and the median host time of a tick without a read (the driver's own
    cost: a goal SYNC_WRITE returns without waiting)."""
    write_only: list[float] = []
    rates = []
    i = 0
    for _ in range(repeats):
        first = driver.counters.ticks
        t0 = time.perf_counter()
        while (now := time.perf_counter()) - t0 < seconds:
            status = driver.tick(frames[i % len(frames)], now)
            if not status.read:
                write_only.append(time.perf_counter() - now)
            i += 1
            if status.state is not RigState.RUNNING:
                raise SystemExit(f"rig left RUNNING: {status.state.value} {status.fault}")
        rates.append((driver.counters.ticks - first) / (time.perf_counter() - t0))
    return max(rates), statistics.median(write_only), status.counters


def sdk_rate(port_name: str, rig: RigConfig, baud: int, seconds: float, repeats: int) -> float:
    """The SDK alone: goal SYNC_WRITE every tick, FAST_SYNC_READ every divider ticks
    (on a RigPort, so its reply timeouts count the queued bytes as the driver's do).
    Best of ``repeats`` windows."""
    port = RigPort(port_name, rig.bus.latency_timer_ms, rig.bus.timeout_margin_ms)
    port.openPort()
    port.setBaudRate(baud)
    packets = sdk.PacketHandler(2.0)
    writer = sdk.GroupSyncWrite(port, packets, 116, 4)
    reader = sdk.GroupSyncRead(port, packets, 132, READ_BYTES)
    for servo in rig.servos.values():
        writer.addParam(servo.id, [0, 8, 0, 0])
        reader.addParam(servo.id)
    divider, failures, rates = rig.bus.read_divider, 0, []
    for _ in range(repeats):
        ticks = 0
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            writer.txPacket()
            ticks += 1
            if ticks % divider == 0 and reader.fastSyncRead() != sdk.COMM_SUCCESS:
                failures += 1
        rates.append(ticks / (time.perf_counter() - t0))
    port.closePort()
    if failures:
        print(f"  (bare SDK: {failures} failed reads)")
    return max(rates)


def _press(driver: RigDriver, pressed: list[float]) -> None:
    """The e-stop button, pressed from another thread at a random moment."""
    time.sleep(random.uniform(0.05, 0.15))
    pressed.append(time.perf_counter())
    driver.estop()


def estop_latencies(
    driver: RigDriver, emu: Emulator, frames: list[list[float]], trials: int, hz: float
) -> tuple[list[float], list[float]]:
    """(estop() -> torque-off packet written by the host, -> fully arrived at the emulator)."""
    written, arrived_all = [], []
    tick_s = 1.0 / hz
    for _ in range(trials):
        start(driver, frames)
        emu.ask("torque_off_at")  # forget the start-up's own torque writes
        pressed: list[float] = []
        presser = threading.Thread(target=_press, args=(driver, pressed))
        presser.start()
        next_tick, i = time.perf_counter(), 0
        while driver.state is RigState.RUNNING:
            driver.tick(frames[i % len(frames)], time.perf_counter())
            i += 1
            next_tick += tick_s
            time.sleep(max(0.0, next_tick - time.perf_counter()))
        presser.join()
        arrived = emu.ask("torque_off_at")
        last_packet = driver.last_packet_at  # nothing is written after the e-stop's packet
        if arrived is None or not pressed or last_packet is None:
            raise SystemExit("no torque-off write reached the emulator")
        written.append(last_packet - pressed[0])
        arrived_all.append(arrived - pressed[0])
    return written, arrived_all


class Emulator:
    """The timed emulator in a child process."""

    def __init__(self, rig: RigConfig, baud: int, wire_timing: bool) -> None:
        self.conn, child = mp.Pipe()
        context = mp.get_context("fork")
        self.process = context.Process(target=_serve, args=(child, rig, baud, wire_timing), daemon=True)
        self.process.start()
        self.port: str = self.conn.recv()

    def ask(self, command: str) -> Any:
        self.conn.send(command)
        return self.conn.recv()

    def stop(self) -> None:
        self.ask("stop")
        self.process.join(timeout=5)


def bench(baud: int, seconds: float, repeats: int, trials: int, estop_hz: float) -> dict[str, Any]:
    base = load_rig("full_rider")
    # generous reply timeouts: the loop waits for the emulator instead of counting false timeouts
    changes = {
        "baud": baud,
        "soft_start_s": 0.2,
        "timeout_margin_ms": 50.0,
        "reply_budget_s": 2.0,
        "setup_retry_s": 5.0,
        "bus_watchdog_ms": 1000,
    }
    rig = base.model_copy(update={"bus": base.bus.model_copy(update=changes)})
    frames = trot_frames(2000, rig.bus.tick_hz)
    untimed = Emulator(rig, baud, wire_timing=False)
    try:
        emulator_hz = sdk_rate(untimed.port, rig, baud, seconds, repeats)
    finally:
        untimed.stop()
    emu = Emulator(rig, baud, wire_timing=True)
    try:
        raw = sdk_rate(emu.port, rig, baud, seconds, repeats)
        emu.ask("settle")  # let the emulator drain what the bare loop queued
        driver = RigDriver(rig, port=emu.port)
        start(driver, frames)
        rate, host_s, counters = driver_rate(driver, frames, seconds, repeats)
        driver.estop()
        written, arrived = estop_latencies(driver, emu, frames, trials, estop_hz)
        driver.close()
    finally:
        emu.stop()
    n = len(rig.servos)
    wire_bytes = wire_bytes_per_tick(n, rig.bus.read_divider)
    wire_rate = baud / 10 / wire_bytes
    return {
        "baud": baud,
        "servos": n,
        "divider": rig.bus.read_divider,
        "wire_bytes": wire_bytes,
        "wire_hz": wire_rate,
        "sdk_hz": raw,
        "emulator_hz": emulator_hz,
        "driver_hz": rate,
        "host_write_ms": host_s * 1000,
        "read_failures": counters["read_failures"],
        "estop_written_ms": [x * 1000 for x in written],
        "estop_ms": [x * 1000 for x in arrived],
        "tick_ms": 1000.0 / estop_hz,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=1.5, help="length of one rate window")
    parser.add_argument("--repeats", type=int, default=3, help="rate windows (the best one counts)")
    parser.add_argument("--trials", type=int, default=8, help="e-stop trials per baud")
    parser.add_argument("--estop-hz", type=float, default=100.0, help="tick rate during the e-stop trials")
    parser.add_argument("--bauds", type=int, nargs="+", default=[1_000_000, 4_000_000])
    args = parser.parse_args()
    sys.setswitchinterval(0.0005)
    print(f"24 emulated servos (config/rigs/full_rider.toml), wire timing on, {len(RIDER)} rider channels")
    ok = True
    for baud in args.bauds:
        r = bench(baud, args.seconds, args.repeats, args.trials, args.estop_hz)
        ratio = r["driver_hz"] / r["wire_hz"]
        estop = r["estop_ms"]
        limit = r["tick_ms"] + 1.0
        ok &= ratio >= 0.8 and max(estop) <= limit
        host_hz = 1000.0 / r["host_write_ms"]
        sdk_hz, emu_hz, wire_hz = r["sdk_hz"], r["emulator_hz"], r["wire_hz"]
        print(f"\n{baud / 1e6:g} Mbps, read divider {r['divider']}: {r['wire_bytes']:.0f} wire bytes per tick")
        print(f"  wire allows               {wire_hz:7.0f} ticks/s")
        print(f"  SDK alone, no wire timing {emu_hz:7.0f} ticks/s   (the emulator's own ceiling here)")
        print(f"  SDK alone, wire timing    {sdk_hz:7.0f} ticks/s   ({sdk_hz / wire_hz:.2f} of the wire)")
        print(
            f"  driver, wire timing       {r['driver_hz']:7.0f} ticks/s   ratio to the wire {ratio:.2f} "
            f"(target >= 0.8); to the SDK alone {r['driver_hz'] / sdk_hz:.2f}; {r['read_failures']} failed reads"
        )
        print(f"  driver host time per write-only tick {r['host_write_ms']:.3f} ms (the driver alone: {host_hz:.0f}/s)")
        written = r["estop_written_ms"]
        print(
            f"  e-stop at {1000 / r['tick_ms']:.0f} ticks/s, {len(estop)} trials (target <= {limit:.1f} ms: one "
            f"{r['tick_ms']:.1f} ms tick + 1 ms):"
        )
        for what, values in (("written by the host", written), ("arrived on the wire", estop)):
            median, worst = statistics.median(values), max(values)
            print(f"    estop() -> torque-off {what:20s} median {median:6.2f} ms, max {worst:6.2f} ms")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
