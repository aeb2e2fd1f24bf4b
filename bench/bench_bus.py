"""The rig device on a 24-servo emulated bus with wire timing: loop rate, e-stop, soak.

    PYTHONPATH=$PWD .venv/bin/python bench/bench_bus.py [--seconds 1.5] [--bauds 1000000 4000000]
    PYTHONPATH=$PWD .venv/bin/python bench/bench_bus.py --soak [--runs 20] [--run-seconds 60] [--burners 2] [--logs DIR]
    PYTHONPATH=$PWD .venv/bin/python bench/bench_bus.py --soak --in-process [--runs 20] [--run-seconds 60]

The emulator runs in a child process (bench/rig_fixtures.py) and holds every packet on
the wire for bytes x 10 / baud.

Loop rate: the device RUNNING, unpaced, one goal SYNC_WRITE per tick and a Fast Sync
Read of 15 bytes every ``read_divider`` ticks, against two baselines from the same run:
the rate the wire allows (target ratio >= 0.8) and the bare SDK doing the same
transactions (the device's overhead).

Soak (issue 24, ``--soak``): the rig through the real service on a loaded host
(bench/bus_soak.py): faults, false hangs, deaths and their exit status, tick gaps, vanish
detection; the server's log of every run gone wrong kept in ``--logs``.

In-process soak (issue 10, ``--soak --in-process``): ``--runs`` runs of ``--run-seconds`` of the shipped 24-servo map
(config/rigs/full_rider.toml, its own budgets and timeouts, nothing relaxed) at its
tick rate, trotting, with the other core busy: faults (target 0), read failures and
retries, Fast Sync Read fallbacks (none may be permanent), overruns, the device's CPU
time per tick, and its loop rate against the wire-limited rate.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import dynamixel_sdk as sdk

from bench.bus_soak import service_soak
from bench.rig_fixtures import Emulator, other_core_busy
from riderlive.devices.budget import ReplyTimer
from riderlive.devices.device import Device
from riderlive.devices.lifecycle import DeviceState
from riderlive.dynamixel.driver import rig_device
from riderlive.dynamixel.rig import READ_BYTES, RigConfig, load_rig, wire_bytes_per_tick
from riderlive.dynamixel.sdkbus import RigPort
from riderlive.horse import DEFAULT_SCALE, ProceduralHorse
from riderlive.rules import RiderModel
from riderlive.sched import try_realtime_priority
from riderlive.tickframe import Flag, TickFrame

S = DeviceState


def trot_frames(count: int, hz: float) -> list[TickFrame]:
    """``count`` tick frames of a procedural trot at ``hz`` (the rider and the horse it rode)."""
    horse, model = ProceduralHorse("trot"), RiderModel(scale=DEFAULT_SCALE)
    frames = []
    for i in range(count):
        t = i / hz
        sample = horse.sample(t)
        frames.append(TickFrame.build(i, t, t, t, Flag.PROCEDURAL, model.evaluate(sample), sample))
    return frames


def start(device: Device, frames: list[TickFrame], timeout: float = 60.0) -> None:
    """Connect (or reset), arm, tick until RUNNING."""
    tick_s = device.period_s
    if device.state is S.DISCONNECTED:
        device.connect("bench")
    deadline = time.perf_counter() + timeout
    i = 0
    while time.perf_counter() < deadline and device.state is not S.RUNNING:
        if device.state in (S.DISARMED, S.PARKED):
            device.arm(device.name, "bench")
        elif device.state in (S.ESTOP, S.FAULT):
            device.reset("bench")
        device.tick(frames[i % len(frames)], time.perf_counter())
        i += 1
        time.sleep(tick_s)
    if device.state is not S.RUNNING:
        raise SystemExit(f"the rig did not start: {device.state.value}, {device.fault}")


def device_rate(
    device: Device, frames: list[TickFrame], seconds: float, repeats: int
) -> tuple[float, float, dict[str, int]]:
    """Ticks per second, unpaced, while RUNNING (best of ``repeats`` windows: the machine
    is shared); and the median host time of a tick without a read."""
    write_only: list[float] = []
    rates = []
    i = 0
    for _ in range(repeats):
        first = device.counters["ticks"]
        t0 = time.perf_counter()
        while (now := time.perf_counter()) - t0 < seconds:
            status = device.tick(frames[i % len(frames)], now)
            if not status.extra["read"]:
                write_only.append(time.perf_counter() - now)
            i += 1
            if status.state is not S.RUNNING:
                raise SystemExit(f"rig left RUNNING: {status.state.value} {status.fault}")
        rates.append((device.counters["ticks"] - first) / (time.perf_counter() - t0))
    return max(rates), statistics.median(write_only), status.counters


def sdk_rate(port_name: str, rig: RigConfig, baud: int, seconds: float, repeats: int) -> float:
    """The SDK alone: goal SYNC_WRITE every tick, FAST_SYNC_READ every divider ticks."""
    port = RigPort(port_name, rig.bus.latency_timer_ms, ReplyTimer(floor_ms=50.0, ceiling_ms=50.0))
    port.openPort()
    port.setBaudRate(baud)
    packets = sdk.PacketHandler(2.0)
    writer = sdk.GroupSyncWrite(port, packets, 116, 4)
    reader = sdk.GroupSyncRead(port, packets, 132, READ_BYTES)
    for servo in rig.servos.values():
        writer.addParam(servo.id, [0, 8, 0, 0])
        reader.addParam(servo.id)
    divider, rates = rig.bus.read_divider, []
    for _ in range(repeats):
        ticks = 0
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            writer.txPacket()
            ticks += 1
            if ticks % divider == 0:
                reader.fastSyncRead()
        rates.append(ticks / (time.perf_counter() - t0))
    port.closePort()
    return max(rates)


def rate_bench(baud: int, seconds: float, repeats: int) -> dict[str, Any]:
    base = load_rig("full_rider")
    changes = {"baud": baud, "soft_start_s": 0.2, "reply_budget_s": 2.0, "setup_retry_s": 5.0, "bus_watchdog_ms": 1000}
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
        emu.ask("stats")  # let the emulator drain what the bare loop queued
        device = rig_device(rig, port=emu.port)
        start(device, frames)
        rate, host_s, counters = device_rate(device, frames, seconds, repeats)
        device.close()
    finally:
        emu.stop()
    wire_bytes = wire_bytes_per_tick(len(rig.servos), rig.bus.read_divider)
    return {
        "baud": baud,
        "divider": rig.bus.read_divider,
        "wire_bytes": wire_bytes,
        "wire_hz": baud / 10 / wire_bytes,
        "sdk_hz": raw,
        "emulator_hz": emulator_hz,
        "device_hz": rate,
        "host_write_ms": host_s * 1000,
        "read_failures": counters.get("read_failures", 0),
    }


def soak_run(rig: RigConfig, seconds: float, frames: list[TickFrame]) -> dict[str, Any]:
    """One paced run of the shipped map: what went wrong, what it cost. The loop runs at
    SCHED_FIFO 50 as the service's tick does, the emulator at 60 (it stands in for servos)."""
    emu = Emulator(rig, priority=60)
    try:
        device = rig_device(rig, port=emu.port)
        start(device, frames)
        period = rig.bus.tick_s
        cpu: list[float] = []
        overruns = 0
        t0 = next_tick = time.perf_counter()
        i = 0
        states = set()
        while time.perf_counter() - t0 < seconds:
            c0 = time.thread_time()
            status = device.tick(frames[i % len(frames)], time.perf_counter())
            cpu.append(time.thread_time() - c0)
            states.add(status.state)
            i += 1
            next_tick += period
            late = time.perf_counter() - next_tick
            if late > 0:
                overruns += 1
                next_tick = time.perf_counter()
            else:
                time.sleep(-late)
        elapsed = time.perf_counter() - t0
        counters = dict(device.counters) | dict(device.plug.counters)
        fast_at_end = bool(device.plug.status()["fast_sync_read"])
        fault = device.fault
        device.close()
    finally:
        emu.stop()
    return {
        "faults": counters.get("faults", 0),
        "fault": None if fault is None else fault.message,
        "left_running": states != {S.RUNNING},
        "read_failures": counters.get("read_failures", 0),
        "reads": counters.get("reads", 0),
        "fallbacks": counters.get("fast_read_fallbacks", 0),
        "fast_at_end": fast_at_end,
        "overruns": overruns,
        "ticks_hz": i / elapsed,
        "cpu_ms": 1000 * statistics.mean(cpu),
        "cpu_p99_ms": 1000 * sorted(cpu)[int(0.99 * len(cpu))],
    }


def soak(runs: int, seconds: float, busy: bool) -> int:
    rig = load_rig("full_rider")
    frames = trot_frames(3000, rig.bus.tick_hz)
    wire_hz = rig.bus.baud / 10 / wire_bytes_per_tick(len(rig.servos), rig.bus.read_divider)
    print(
        f"soak: {runs} x {seconds:g} s of full_rider as shipped ({len(rig.servos)} servos, {rig.bus.baud} baud, "
        f"{rig.bus.tick_hz:g} ticks/s, wire timing), other core busy: {busy}"
    )
    results = []
    print(f"  real-time priority: {try_realtime_priority(50)}")
    with other_core_busy(runs * (seconds + 30), busy):
        for n in range(runs):
            r = soak_run(rig, seconds, frames)
            results.append(r)
            print(
                f"  run {n + 1:2d}: faults {r['faults']} {r['fault'] or ''} fallbacks {r['fallbacks']} "
                f"(fast at end: {r['fast_at_end']}) read failures {r['read_failures']}/{r['reads']} "
                f"overruns {r['overruns']} {r['ticks_hz']:.1f} ticks/s, cpu {r['cpu_ms']:.3f} ms/tick "
                f"(p99 {r['cpu_p99_ms']:.3f})",
                flush=True,
            )
    faults = sum(r["faults"] for r in results)
    permanent = sum(1 for r in results if not r["fast_at_end"] and r["fallbacks"])
    failures = sum(r["read_failures"] for r in results)
    reads = sum(r["reads"] for r in results)
    cpu = statistics.mean(r["cpu_ms"] for r in results)
    hz = statistics.mean(r["ticks_hz"] for r in results)
    print(
        f"\n{runs} runs: faults {faults} (target 0), runs that ended on the plain read {permanent} (target 0), "
        f"fallbacks {sum(r['fallbacks'] for r in results)}, read failures {failures} of {reads + failures} reads "
        f"({failures / max(1, reads + failures):.2%}, retried), paced loop {hz:.1f} ticks/s "
        f"(tick_hz {rig.bus.tick_hz:g}; the wire allows {wire_hz:.0f}), device CPU {cpu:.3f} ms per tick"
    )
    return 0 if faults == 0 and permanent == 0 else 1


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=1.5, help="length of one rate window")
    parser.add_argument("--repeats", type=int, default=3, help="rate windows (the best one counts)")
    parser.add_argument("--bauds", type=int, nargs="+", default=[1_000_000, 4_000_000])
    parser.add_argument("--soak", action="store_true", help="the soak instead of the rate")
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--run-seconds", type=float, default=60.0)
    parser.add_argument("--idle", action="store_true", help="do not keep the other core busy")
    parser.add_argument("--in-process", action="store_true", help="the soak of the device alone (issue 10)")
    parser.add_argument("--burners", type=int, default=2, help="normal-priority busy loops in the service soak")
    parser.add_argument("--web-priority", type=int, default=10, help="server.realtime_priority in the service soak")
    parser.add_argument(
        "--kernel-workers",
        type=int,
        default=0,
        help="host.kernel_workers_priority: unbound kernel workers at this SCHED_FIFO (0: off; service/kworkers.py)",
    )
    parser.add_argument(
        "--logs", type=Path, default=None, help="service soak: where the logs go (default: a new temp dir)"
    )
    args = parser.parse_args()
    sys.setswitchinterval(0.0005)
    if args.soak and not args.in_process:
        burners = 0 if args.idle else args.burners
        return service_soak(args.runs, args.run_seconds, burners, args.web_priority, args.logs, args.kernel_workers)
    if args.soak:
        return soak(args.runs, args.run_seconds, not args.idle)
    ok = True
    for baud in args.bauds:
        r = rate_bench(baud, args.seconds, args.repeats)
        ratio = r["device_hz"] / r["wire_hz"]
        ok &= ratio >= 0.8
        sdk_hz, emu_hz, wire_hz = r["sdk_hz"], r["emulator_hz"], r["wire_hz"]
        print(f"\n{baud / 1e6:g} Mbps, read divider {r['divider']}: {r['wire_bytes']:.0f} wire bytes per tick")
        print(f"  wire allows               {wire_hz:7.0f} ticks/s")
        print(f"  SDK alone, no wire timing {emu_hz:7.0f} ticks/s   (the emulator's own ceiling here)")
        print(f"  SDK alone, wire timing    {sdk_hz:7.0f} ticks/s   ({sdk_hz / wire_hz:.2f} of the wire)")
        print(
            f"  device, wire timing       {r['device_hz']:7.0f} ticks/s   ratio to the wire {ratio:.2f} "
            f"(target >= 0.8); to the SDK alone {r['device_hz'] / sdk_hz:.2f}; {r['read_failures']} failed reads"
        )
        print(f"  device host time per write-only tick {r['host_write_ms']:.3f} ms")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
