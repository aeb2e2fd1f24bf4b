"""The rig through the real service on a busy host: faults, false hangs, vanish detection.

    PYTHONPATH=$PWD .venv/bin/python bench/bench_bus.py --soak [--runs 20] [--run-seconds 60] [--burners 2]

``riderlive serve`` (tick at 120 Hz at its documented SCHED_FIFO 50, the web process at
``server.realtime_priority`` 10 as docs/hardware.md asks near people) drives bench3 fitted
to 120 Hz (bench/rig_fixtures.py ``bench_rig``: its shipped ``reply_budget_s`` 0.1 s and
``bus_watchdog_ms`` 100) on the emulated bus (a child process at SCHED_FIFO 60, wire
timing), with ``--burners`` normal-priority busy loops (2: both cores loaded). Each run:
arm, ``--run-seconds`` armed (a rig that leaves ``running`` is a fault: counted, its
message kept, reset and armed again), then servo 2 vanishes: the time from the vanish to
the rig's ``no_reply`` fault (target <= 150 ms: the budget, one read period, the tick).

The baseline from the same run: every ``stall_ridethroughs`` count is a silence that
outlived the budget on the wall clock only because the host stalled; before the stall
discount (riderlive/devices/stall.py) each would have been a ``no_reply`` fault.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx

from bench.rig_fixtures import Emulator, bench_rig, other_core_busy
from riderlive.dynamixel.emulator_faults import FaultKind, FaultSpec
from tests.service.live_server import LiveServer

TOKEN = "soak-token-1"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
VANISHING = 2


def device(client: httpx.Client) -> dict[str, Any]:
    payload: dict[str, Any] = client.get("/api/devices").json()
    devices = payload["devices"] or [{"state": "none", "counters": {}}]  # a new tick not yet up
    return dict(devices[0]) | {"supervision": payload["supervision"]}


def wait_state(client: httpx.Client, wanted: set[str], timeout: float = 20.0, poll: float = 0.005) -> dict[str, Any]:
    deadline = time.perf_counter() + timeout
    while (d := device(client))["state"] not in wanted:
        if time.perf_counter() > deadline:
            d.pop("servos", None)
            raise SystemExit(f"rig is {d['state']}, wanted {wanted}: {d}")
        time.sleep(poll)
    return d


def arm(client: httpx.Client, name: str, timeout: float = 60.0) -> None:
    deadline = time.perf_counter() + timeout
    while (answer := client.post("/api/arm", json={"device": name})).status_code != 200:
        if time.perf_counter() > deadline:
            raise SystemExit(f"arm refused: {answer.text}")
        time.sleep(0.1)
    wait_state(client, {"running", "fault", "parking"})


def recover(client: httpx.Client) -> None:
    """From a stop (fault, e-stop, a tick restart's disarm) back to ``disarmed``."""
    d = wait_state(client, {"fault", "estop", "disarmed", "parked"}, timeout=60.0)
    if d["state"] in ("fault", "estop"):
        client.post("/api/reset")
        wait_state(client, {"disarmed"})


def vanish(client: httpx.Client, emu: Emulator, name: str, restarts: int) -> tuple[float, str | None, int]:
    """Servo 2 vanishes while running: seconds to the rig's fault (nan: not seen); a tick
    restart meanwhile (a false hang) voids the trial and it is tried again."""
    for _ in range(3):
        wait_state(client, {"running"})
        applied = emu.ask(("fault", FaultSpec(FaultKind.VANISH, VANISHING)))
        deadline = time.perf_counter() + 2.0
        while (d := device(client))["state"] == "running" and time.perf_counter() < deadline:
            if d["supervision"]["restarts"] != restarts:
                break
            time.sleep(0.005)
        emu.ask(("fault", FaultSpec(FaultKind.REAPPEAR, VANISHING)))
        fault = d.get("fault") or {}
        if d["supervision"]["restarts"] == restarts and fault.get("unit") == VANISHING:
            recover(client)
            return fault["at"] - applied, fault.get("message"), restarts
        restarts = d["supervision"]["restarts"]
        recover(client)
        arm(client, name)
    return float("nan"), None, restarts


def soak_run(client: httpx.Client, emu: Emulator, name: str, seconds: float) -> dict[str, Any]:
    before = device(client)
    restarts = before["supervision"]["restarts"]
    faults: list[str] = []
    arm(client, name)
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        d = device(client)
        if d["supervision"]["restarts"] != restarts:  # the tick restarted: the rig was parked by the guardian
            restarts = d["supervision"]["restarts"]
            faults.append(f"tick restarted: {d['supervision']['last_exit']}")
            recover(client)
            arm(client, name)
        elif d["state"] != "running":
            faults.append(f"{d['state']}: {(d.get('fault') or {}).get('message')}")
            recover(client)
            arm(client, name)
        time.sleep(0.25)
    detected, message, _ = vanish(client, emu, name, restarts)
    after = device(client)
    old = before["counters"]  # a restarted tick's rig counts from 0 (an undercount then)
    counts = {k: v - old.get(k, 0) if v >= old.get(k, 0) else v for k, v in after["counters"].items()}
    sup = {k: after["supervision"][k] - before["supervision"][k] for k in ("hangs", "restarts", "deaths")}
    return {**counts, "fault_messages": faults, "vanish_s": detected, "vanish_fault": message, **sup}


def service_soak(runs: int, seconds: float, burners: int, web_priority: int) -> int:
    with tempfile.TemporaryDirectory() as tmp:
        workdir = Path(tmp)
        rig = bench_rig(workdir / "soak.toml", 120.0, 1_000_000, soft_start_s=0.3, park_s=0.3)
        print(
            f"service soak: {runs} x {seconds:g} s armed, bench3 at 120 Hz (reply_budget_s {rig.bus.reply_budget_s:g}, "
            f"read every {rig.bus.read_divider} ticks, bus_watchdog_ms {rig.bus.bus_watchdog_ms}), tick SCHED_FIFO 50, "
            f"web SCHED_FIFO {web_priority}, {burners} normal-priority burners"
        )
        emu = Emulator(rig, priority=60)
        config = (
            f"[server]\nrealtime_priority = {web_priority}\n"
            f'[tick]\nrate = 120.0\n[security]\ntoken = "{TOKEN}"\n'
            f'[rig]\nfile = "{workdir / "soak.toml"}"\nport = "{emu.port}"\n'
        )
        results = []
        live = LiveServer(config, workdir, token=TOKEN)
        try:
            client = httpx.Client(base_url=live.base, headers=AUTH, timeout=10.0)
            wait_state(client, {"disarmed"}, 30.0)
            with other_core_busy(runs * (seconds + 60), burners > 0, burners):
                for n in range(runs):
                    r = soak_run(client, emu, rig.name, seconds)
                    results.append(r)
                    print(
                        f"  run {n + 1:2d}: faults {len(r['fault_messages'])} {'; '.join(r['fault_messages'])} "
                        f"hangs {r['hangs']} restarts {r['restarts']} ridden-through silences "
                        f"{r.get('stall_ridethroughs', 0)} read failures {r.get('read_failures', 0)}/"
                        f"{r.get('reads', 0)}; vanish detected in {r['vanish_s'] * 1000:.1f} ms",
                        flush=True,
                    )
            client.close()
        finally:
            live.stop()
            emu.stop()
            warnings = [line.strip() for line in live.log if "warning:" in line]
    faults = sum(1 for r in results for m in r["fault_messages"] if not m.startswith("tick restarted"))
    hangs = sum(r["hangs"] for r in results)
    ridden = sum(r.get("stall_ridethroughs", 0) for r in results)
    vanish = sorted(r["vanish_s"] * 1000 for r in results if r["vanish_s"] == r["vanish_s"])
    vanish = vanish or [float("nan")]
    print(f"\nserve's start warnings: {warnings or 'none'}")
    print(
        f"{runs} runs: faults {faults} (target 0; without the stall discount {faults + ridden}: "
        f"{ridden} silences ridden through), false hangs {hangs} (target 0), restarts "
        f"{sum(r['restarts'] for r in results)}; vanish detected in median {statistics.median(vanish):.1f} ms, "
        f"max {vanish[-1]:.1f} ms (target <= 150)"
    )
    return 0 if faults == 0 and hangs == 0 and vanish[-1] <= 150.0 else 1
