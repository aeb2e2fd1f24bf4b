"""A stage over NATS: fan-out against /ws/rider in the same run, and the stage e-stop.

    PYTHONPATH=$PWD .venv/bin/python bench/bench_nats.py [--rigs 4] [--subscribers 16] [--seconds 5]
        [--trials 20] [--idle] [--realtime]

A real ``nats-server`` (PyPI) on loopback; ``--rigs`` services (``riderlive serve --nats``,
tick at 120 Hz, each driving bench3 on its own emulated bus in a child process); the other
core busy (``--idle`` to leave it). By default the ticks and the emulators run at normal
priority (four rigs that would each have a computer share 2 cores here); ``--realtime``
runs them as deployed, the ticks at SCHED_FIFO 50 and each emulator (standing in for the
servos, which answer in microseconds) at 60. Measured:

1. **Fan-out**: ``--subscribers`` clients in one other process, spread over the rigs,
   first as NATS subscribers of ``...<rig>.frame`` for ``--seconds``, then as
   ``/ws/rider`` clients (binary, with the horse: the same payload) for as long.
   Delivery (frames received / frames the rig published in the window) and
   tick-to-receive latency (receive time minus the tick's engine time on the shared
   CLOCK_MONOTONIC, so both paths include the tick -> web process hop), p50 / p99.
2. **Stage e-stop**: every rig armed and running, a random 50-150 ms, then one message on
   ``riderlive.v1.<stage>.estop``; per trial the time until the torque-off packet has
   arrived on *every* emulated bus (max over rigs), p50 / p99 / max over ``--trials``,
   split at the rigs' acknowledged latch time (``latched_at``, the same clock): message ->
   latched by every rig's web process, and latched -> torque off (the tick and the bus).
3. **Stage heartbeat lost**: every rig running, the heartbeat stops; the time until the
   torque-off packet (after parking) has arrived on every bus.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing as mp
import random
import statistics
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bench.rig_fixtures import Emulator, bench_rig, other_core_busy, torque_offs
from riderlive.bus.broker import Broker
from riderlive.bus.stage import beat, discover, stage_estop
from riderlive.bus.subjects import Kind, Stage
from riderlive.channels import HORSE_NAMES
from riderlive.service.rider_frames import decode_binary_frame
from tests.bus.harness import NatsProbe, start_rig
from tests.service.live_server import LiveServer

TOKEN = "bench-token-1"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
STAGE = Stage("bench")
HEARTBEAT_TIMEOUT = 0.5


async def _subscribe(kind: str, targets: list[tuple[str, str, float]], seconds: float) -> list[dict[str, Any]]:
    """``targets``: (rig, url, perf_origin) per subscriber; per subscriber: latencies and seqs."""
    results: list[dict[str, Any]] = [{"rig": rig, "lat": [], "seq": [], "error": None} for rig, _, _ in targets]
    # each subscriber counts ``seconds`` from the moment it is subscribed (a first hello
    # can take seconds on a loaded machine)

    def note(i: int, data: bytes) -> None:
        now = time.perf_counter()
        frame = decode_binary_frame(data)
        results[i]["lat"].append(now - (targets[i][2] + frame["t"]))
        results[i]["seq"].append(frame["seq"])

    async def nats_sub(i: int) -> None:
        from riderlive.bus.nats import connect
        from riderlive.bus.transport import Message

        rig, url, _ = targets[i]
        transport = await connect(url, name=f"bench sub {i}")

        async def on(msg: Message) -> None:
            note(i, msg.data)

        await transport.subscribe(STAGE.rig(rig).subject(Kind.FRAME), on, 1 << 16)
        await transport.flush()
        await asyncio.sleep(seconds)
        await transport.close()

    async def ws_sub(i: int) -> None:
        from websockets.asyncio.client import connect

        _, url, _ = targets[i]
        async with connect(url + "/ws/rider", max_size=1 << 22) as ws:
            await ws.send(json.dumps({"type": "subscribe", "encoding": "binary", "horse_channels": list(HORSE_NAMES)}))
            while isinstance(message := await ws.recv(), str) and '"subscribed"' not in message:
                pass
            stop_at = time.perf_counter() + seconds
            while (left := stop_at - time.perf_counter()) > 0:
                try:
                    message = await asyncio.wait_for(ws.recv(), left)
                except TimeoutError:
                    break
                if isinstance(message, bytes):
                    note(i, message)

    async def guarded(i: int) -> None:
        try:
            await (nats_sub if kind == "nats" else ws_sub)(i)
        except Exception as exc:  # reported with the figures
            results[i]["error"] = repr(exc)

    await asyncio.gather(*(guarded(i) for i in range(len(targets))))
    return results


def _subscriber_process(kind: str, targets: list[tuple[str, str, float]], seconds: float, conn: Any) -> None:
    conn.send(asyncio.run(_subscribe(kind, [(r, u, o) for r, u, o in targets], seconds)))


def fan_out(kind: str, targets: list[tuple[str, str, float]], seconds: float) -> list[dict[str, Any]]:
    parent, child = mp.Pipe()
    process = mp.get_context("spawn").Process(target=_subscriber_process, args=(kind, targets, seconds, child))
    process.start()
    results: list[dict[str, Any]] = parent.recv()
    process.join(10)
    return results


def summarize(results: list[dict[str, Any]]) -> tuple[float, float, float]:
    """Delivery (fraction), p50 and p99 latency (ms) over every subscriber."""
    spans: dict[str, tuple[int, int]] = {}
    for r in results:
        if r["seq"]:
            low, high = spans.get(r["rig"], (r["seq"][0], r["seq"][-1]))
            spans[r["rig"]] = (min(low, r["seq"][0]), max(high, r["seq"][-1]))
    expected = sum(spans[r["rig"]][1] - spans[r["rig"]][0] + 1 for r in results if r["rig"] in spans)
    received = sum(len(set(r["seq"])) for r in results)
    lat = sorted(x * 1000 for r in results for x in r["lat"])
    if not lat:
        return 0.0, float("nan"), float("nan")
    return received / max(expected, 1), statistics.median(lat), p99(lat)


def p99(ordered: list[float]) -> float:
    """The 99th percentile of an ascending list (its largest value below 100 samples)."""
    return ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))]


def report(label: str, results: list[dict[str, Any]]) -> None:
    errors = sorted({str(r["error"])[:120] for r in results if r["error"]})
    if errors:
        print(f"  {label:8s} subscribers that failed: {sum(1 for r in results if r['error'])}: {errors}")
    delivery, p50, p99 = summarize(results)
    print(
        f"  {label:8s} delivery {100 * delivery:6.2f} %   tick->receive p50 {p50:6.2f}  p99 {p99:7.2f} ms", flush=True
    )


def rig_state(live: LiveServer) -> str:
    devices = live.get("/api/devices", headers=AUTH).json()["devices"]
    return str(devices[0]["state"]) if devices else "none"


def wait_all(lives: list[LiveServer], wanted: str, timeout: float = 20.0) -> None:
    deadline = time.perf_counter() + timeout
    while any(rig_state(live) != wanted for live in lives):
        if time.perf_counter() > deadline:
            devices = [live.get("/api/devices", headers=AUTH).json()["devices"] for live in lives]
            supervision = [live.get("/api/state", headers=AUTH).json().get("supervision") for live in lives]
            logs = ["".join(live.log[-15:]) for live in lives]
            raise SystemExit(
                f"rigs are {[rig_state(x) for x in lives]}, wanted {wanted}: {devices}\n"
                f"supervision: {supervision}\n" + "\n".join(logs)
            )
        time.sleep(0.01)


def post(live: LiveServer, path: str, body: dict[str, Any] | None = None) -> int:
    return live.request("POST", path, json=body, headers=AUTH).status_code


def arm_all(lives: list[LiveServer], faults: list[str]) -> None:
    """Arm every rig; a rig that faults (its emulator starved on a loaded machine) is reset,
    noted in ``faults`` and armed again."""
    for _ in range(10):
        states = [rig_state(live) for live in lives]
        if all(s == "running" for s in states):
            return
        for live, s in zip(lives, states, strict=True):
            if s == "estop":  # e.g. a guardian that lost a starved web process: counted with the faults
                faults.append("estop latched while not armed")
                post(live, "/api/reset")
            elif s == "fault":
                device = live.get("/api/devices", headers=AUTH).json()["devices"][0]
                faults.append(str((device.get("fault") or {}).get("message")))
                post(live, "/api/reset")
            elif s in ("disarmed", "parked"):
                post(live, "/api/arm", {"device": "bench3"})
        deadline = time.perf_counter() + 10.0
        while time.perf_counter() < deadline:
            states = [rig_state(live) for live in lives]
            if all(s == "running" for s in states) or "fault" in states:
                break
            time.sleep(0.02)
    raise SystemExit(f"the rigs would not run: {[rig_state(x) for x in lives]}; faults: {faults}")


@dataclass
class EstopTrial:
    """One stage e-stop, seconds from the message sent (max over the rigs)."""

    torque_off: float
    """Until the torque-off packet arrived on the last bus."""
    latched: float
    """Until the last rig's web process latched it (its acknowledgement's ``latched_at``)."""
    after_latch: float
    """The longest latch -> torque-off on one rig (the tick and the bus)."""


def estop_trials(
    lives: list[LiveServer], emus: list[Emulator], probe: NatsProbe, trials: int
) -> tuple[list[EstopTrial], list[str]]:
    results: list[EstopTrial] = []
    faults: list[str] = []
    for n in range(trials):
        arm_all(lives, faults)
        for emu in emus:
            emu.ask("arrivals")
        time.sleep(random.uniform(0.05, 0.15))
        sent = time.perf_counter()
        acks = probe.call(stage_estop(probe.transport, STAGE, "bench", 1.0))
        wait_all(lives, "estop")
        latched_at = {str(a["rig"]): float(a["latched_at"]) for a in acks}
        offs, after_latch = [], []
        for i, emu in enumerate(emus):
            after = [t for t in torque_offs(emu.ask("arrivals")) if t > sent]
            if not after:
                raise SystemExit(f"trial {n}: no torque-off reached a bus")
            offs.append(after[0] - sent)
            if f"r{i}" in latched_at:
                after_latch.append(after[0] - latched_at[f"r{i}"])
        if len(latched_at) != len(emus):
            raise SystemExit(f"trial {n}: {len(latched_at)} of {len(emus)} rigs acknowledged the e-stop in 1 s")
        results.append(EstopTrial(max(offs), max(latched_at.values()) - sent, max(after_latch)))
        reset_all(lives)
    return results, faults


def quantiles_ms(seconds: list[float]) -> str:
    ms = sorted(s * 1000 for s in seconds)
    return f"p50 {statistics.median(ms):6.2f}  p99 {p99(ms):6.2f}  max {ms[-1]:6.2f} ms"


def reset_all(lives: list[LiveServer], timeout: float = 20.0) -> None:
    """Reset until every rig is disarmed (a tick restarted by a loaded machine may need another)."""
    deadline = time.perf_counter() + timeout
    while any(rig_state(live) != "disarmed" for live in lives):
        if time.perf_counter() > deadline:
            raise SystemExit(f"rigs stay {[rig_state(x) for x in lives]} after reset")
        for live in lives:
            if rig_state(live) in ("estop", "fault"):
                post(live, "/api/reset")
        time.sleep(0.05)


def heartbeat_loss(lives: list[LiveServer], emus: list[Emulator], probe: NatsProbe, stop: asyncio.Event) -> float:
    """Stop the stage heartbeat with every rig running: seconds until torque off on every bus."""
    arm_all(lives, [])
    for emu in emus:
        emu.ask("arrivals")
    stopped = time.perf_counter()
    probe.loop.call_soon_threadsafe(stop.set)
    wait_all(lives, "parked", 30.0)
    offs = []
    for emu in emus:
        after = [t for t in torque_offs(emu.ask("arrivals")) if t > stopped]
        if not after:
            raise SystemExit("heartbeat loss: no torque-off reached a bus")
        offs.append(after[0] - stopped)
    return max(offs)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rigs", type=int, default=4)
    parser.add_argument("--subscribers", type=int, default=16)
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--rate", type=float, default=120.0)
    parser.add_argument("--idle", action="store_true", help="do not keep the other core busy")
    parser.add_argument(
        "--realtime",
        action="store_true",
        help="ticks at SCHED_FIFO 50 and emulators at 60, as deployed (default: both at normal priority)",
    )
    args = parser.parse_args()
    sys.setswitchinterval(0.0005)
    with tempfile.TemporaryDirectory() as tmp, Broker() as broker:
        root = Path(tmp)
        changes: dict[str, Any] = {
            "soft_start_s": 0.1,
            "park_s": 0.2,
            "bus_watchdog_ms": 600,
            "reply_budget_s": 0.5,
            "timeout_margin_ms": 40.0,
        }
        rig = bench_rig(root / "bench3.toml", args.rate, **changes)
        emus = [Emulator(rig, priority=60 if args.realtime else None) for _ in range(args.rigs)]
        lives: list[LiveServer] = []
        probe: NatsProbe | None = None
        try:
            for i, emu in enumerate(emus):
                config = (
                    f"[tick]\nrate = {args.rate}\nrealtime_priority = {str(args.realtime).lower()}\n"
                    f'[security]\ntoken = "{TOKEN}"\n'
                    f'[rig]\nfile = "{root / "bench3.toml"}"\nport = "{emu.port}"\n'
                )
                extra = f"heartbeat_timeout = {HEARTBEAT_TIMEOUT}"
                lives.append(start_rig(root / f"r{i}", broker.url, STAGE.name, f"r{i}", config, extra, token=TOKEN))
            probe = NatsProbe(broker.url)
            stop = asyncio.Event()
            probe.start(lambda: beat(probe.transport, STAGE, 0.05, stop))  # type: ignore[union-attr]
            rigs = {r["rig"]: r for r in probe.call(discover(probe.transport, STAGE, 1.0))}
            names = [f"r{i % args.rigs}" for i in range(args.subscribers)]
            origin = {name: float(rigs[name]["perf_origin"]) for name in rigs}
            busy = not args.idle
            print(
                f"\n{args.rigs} rigs at {args.rate:g} Hz, {args.subscribers} subscribers, other core busy: {busy}, "
                f"ticks and emulators at real-time priority: {args.realtime}"
            )
            with other_core_busy(3600, not args.idle):
                nats = fan_out("nats", [(n, broker.url, origin[n]) for n in names], args.seconds)
                ws = fan_out("ws", [(n, lives[int(n[1:])].ws, origin[n]) for n in names], args.seconds)
                for label, results in (("NATS", nats), ("ws/rider", ws)):
                    report(label, results)
                print(f"  p50 ratio NATS / ws/rider: {summarize(nats)[1] / summarize(ws)[1]:.2f}", flush=True)
                if args.trials:
                    trials, faults = estop_trials(lives, emus, probe, args.trials)
                    print(f"  stage e-stop ({args.trials} trials, each the max over the rigs):")
                    print(f"    message -> torque off on every bus  {quantiles_ms([t.torque_off for t in trials])}")
                    print(f"    message -> latched by every rig     {quantiles_ms([t.latched for t in trials])}")
                    print(f"    latched -> torque off on its bus    {quantiles_ms([t.after_latch for t in trials])}")
                    slowest = sorted(round(t.torque_off * 1000, 1) for t in trials)[-5:]
                    print(f"    slowest trials (ms): {slowest}", flush=True)
                    for live in lives:
                        sup = live.get("/api/state", headers=AUTH).json().get("supervision") or {}
                        if sup.get("restarts"):
                            keys = ("restarts", "hangs", "deaths", "last_exit")
                            print(f"    a tick restarted (a trial then waits for it): {[sup.get(k) for k in keys]}")
                    lost = heartbeat_loss(lives, emus, probe, stop)
                    print(
                        f"  stage heartbeat stopped -> torque off on every bus: {lost * 1000:.0f} ms "
                        f"(heartbeat_timeout {HEARTBEAT_TIMEOUT:g} s + park_s 0.2 s + the checks)"
                    )
                    print(f"  rig faults while arming (reset and armed again): {len(faults)} {sorted(set(faults))[:3]}")
        finally:
            if probe is not None:
                probe.close()
            stoppers = [threading.Thread(target=live.stop) for live in lives]
            for t in stoppers:
                t.start()
            for t in stoppers:
                t.join(30)
            for emu in emus:
                emu.stop()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
