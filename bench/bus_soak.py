"""The rig through the real service on a busy host: faults, false hangs, tick gaps, vanish detection.

    PYTHONPATH=$PWD .venv/bin/python bench/bench_bus.py --soak [--runs 20] [--run-seconds 60] [--burners 2]
        [--logs DIR]

``riderlive serve`` (tick at 120 Hz at its documented SCHED_FIFO 50, the web process at
``server.realtime_priority`` 10 as docs/hardware.md asks near people) drives bench3 fitted
to 120 Hz (bench/rig_fixtures.py ``bench_rig``: its shipped ``reply_budget_s`` 0.1 s and
``bus_watchdog_ms`` 100) on the emulated bus (a child process at SCHED_FIFO 60, wire
timing), with ``--burners`` normal-priority busy loops (2: both cores loaded). Each run:
arm, ``--run-seconds`` armed (a rig that leaves ``running`` is a fault: counted, its
message kept, reset and armed again), then servo 2 vanishes (the emulator's ``vanish``: it
neither hears nor answers; the port stays open): the time from the vanish to the rig's
``no_reply`` fault (target <= 150 ms: the budget, one read period, the tick).

A ``/ws/rider`` client (a thread) takes every frame's engine time: the tick gaps of each
run (p50/p99/max between consecutive ticked frames) include the failovers' outages.
Supervision per run: false hangs, deaths with their exit status, warm takeovers.

Nothing stops the soak but a service that cannot be armed for a whole run: a run that goes
wrong (a fault, a restart, a death, a vanish not seen, a refusal) is counted and the
server's log of that run is kept in ``--logs`` (``run-NN.log``, the whole log in
``serve.log``), with the rig's status at the moment.

The baseline from the same run: every ``stall_ridethroughs`` count is a silence that
outlived the budget on the wall clock only because the host stalled; before the stall
discount (riderlive/devices/stall.py) each would have been a ``no_reply`` fault.
"""

from __future__ import annotations

import json
import math
import os
import statistics
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from websockets.sync.client import connect
from websockets.typing import Subprotocol

from bench.rig_fixtures import Emulator, bench_rig, other_core_busy
from riderlive.dynamixel.emulator.faults import FaultKind, FaultSpec
from riderlive.service.kworkers import census
from tests.service.live_server import LiveServer

TOKEN = "soak-token-1"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
VANISHING = 2
VANISH_WAIT_S = 2.0
"""A vanish not seen as a fault within this long is a miss (its log is kept)."""


class SoakError(RuntimeError):
    """The rig did not get where the soak wanted it (the run is counted as gone wrong)."""


class Frames:
    """Every ``/ws/rider`` frame's engine time (s), from a thread; :meth:`gaps` between two marks."""

    def __init__(self, url: str) -> None:
        self.times: list[float] = []
        self.drops = 0
        self._url = url
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="soak-rider-client", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                protocols = [Subprotocol("riderlive.v1"), Subprotocol(f"riderlive.token.{TOKEN}")]
                with connect(self._url + "/ws/rider", subprotocols=protocols, ping_interval=None) as ws:
                    ws.recv(timeout=10)
                    ws.send(json.dumps({"type": "subscribe"}))
                    while not self._stop.is_set():
                        obj = json.loads(ws.recv(timeout=5))
                        if obj.get("type") == "frame":
                            self.times.append(float(obj["t"]))
            except Exception:
                self.drops += 1
                self._stop.wait(0.2)

    def mark(self) -> int:
        return len(self.times)

    def gaps(self, since: int) -> list[float]:
        """Seconds between consecutive ticked frames since mark ``since`` (a generation's frames
        ticked before the last one's are dropped: they came late from a dead generation)."""
        times = np.asarray(self.times[since:], float)
        return [float(g) for g in np.diff(times) if g > 0] if len(times) > 1 else []

    def close(self) -> None:
        self._stop.set()
        self._thread.join(6.0)


def device(client: httpx.Client) -> dict[str, Any]:
    payload: dict[str, Any] = client.get("/api/devices").json()
    devices = payload["devices"] or [{"state": "none", "counters": {}}]  # a new tick not yet up
    return dict(devices[0]) | {"supervision": payload["supervision"]}


def wait_state(client: httpx.Client, wanted: set[str], timeout: float = 20.0, poll: float = 0.005) -> dict[str, Any]:
    deadline = time.perf_counter() + timeout
    while (d := device(client))["state"] not in wanted:
        if time.perf_counter() > deadline:
            d.pop("servos", None)
            raise SoakError(f"rig is {d['state']}, wanted {wanted}: {d}")
        time.sleep(poll)
    return d


def arm(client: httpx.Client, name: str, timeout: float = 60.0) -> None:
    deadline = time.perf_counter() + timeout
    while (answer := client.post("/api/arm", json={"device": name})).status_code != 200:
        if time.perf_counter() > deadline:
            raise SoakError(f"arm refused: {answer.text}")
        time.sleep(0.1)
    wait_state(client, {"running", "fault", "parking"})


def recover(client: httpx.Client) -> None:
    """From a stop (fault, e-stop, a tick restart's disarm) back to ``disarmed``."""
    d = wait_state(client, {"fault", "estop", "disarmed", "parked"}, timeout=60.0)
    if d["state"] in ("fault", "estop"):
        client.post("/api/reset")
        wait_state(client, {"disarmed"})


def vanish(client: httpx.Client, emu: Emulator, name: str, restarts: int) -> tuple[float, str | None, list[str]]:
    """Servo 2 vanishes while running: seconds to the rig's fault (nan: not seen within
    ``VANISH_WAIT_S``, said in the notes with the rig's status); a tick restart meanwhile
    (a false hang) voids the trial and it is tried again."""
    notes: list[str] = []
    for _ in range(3):
        wait_state(client, {"running"})
        applied = emu.ask(("fault", FaultSpec(FaultKind.VANISH, VANISHING)))
        deadline = time.perf_counter() + VANISH_WAIT_S
        while (d := device(client))["state"] == "running" and time.perf_counter() < deadline:
            if d["supervision"]["restarts"] != restarts:
                break
            time.sleep(0.005)
        emu.ask(("fault", FaultSpec(FaultKind.REAPPEAR, VANISHING)))
        fault = d.get("fault") or {}
        if d["supervision"]["restarts"] == restarts and fault.get("unit") == VANISHING:
            recover(client)
            return fault["at"] - applied, fault.get("message"), notes
        if d["supervision"]["restarts"] == restarts:
            shown = {k: d.get(k) for k in ("state", "fault", "counters")} | {
                "generation": d["supervision"]["generation"]
            }
            notes.append(f"vanish not seen in {VANISH_WAIT_S:g} s: {shown}")
        else:
            notes.append("vanish trial voided by a tick restart")
        restarts = d["supervision"]["restarts"]
        recover(client)
        arm(client, name)
    return float("nan"), None, notes


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
            if d["state"] != "running":  # else already armed again (below, after the same restart's stop)
                recover(client)
                arm(client, name)
        elif d["state"] != "running":
            faults.append(f"{d['state']}: {(d.get('fault') or {}).get('message')}")
            recover(client)
            arm(client, name)
        time.sleep(0.25)
    armed = device(client)["counters"]  # the armed window's counts, before the vanish adds its own
    detected, message, notes = vanish(client, emu, name, restarts)
    after = device(client)
    old = before["counters"]  # a restarted tick's rig counts from 0 (an undercount then)

    def since_start(now: dict[str, int]) -> dict[str, int]:
        return {k: v - old.get(k, 0) if v >= old.get(k, 0) else v for k, v in now.items()}

    counts = since_start(after["counters"])
    keys = ("hangs", "restarts", "deaths", "takeovers", "stalls")
    sup = {k: after["supervision"][k] - before["supervision"][k] for k in keys}
    return {
        **counts,
        "armed_ridethroughs": since_start(armed).get("stall_ridethroughs", 0),
        "fault_messages": faults,
        "vanish_s": detected,
        "vanish_fault": message,
        "notes": notes,
        "last_exit": after["supervision"]["last_exit"] if sup["deaths"] else None,
        **sup,
    }


def percentiles(values: list[float]) -> str:
    if not values:
        return "none"
    a = np.asarray(values) * 1000
    return f"p50 {np.percentile(a, 50):.2f} p99 {np.percentile(a, 99):.2f} max {a.max():.1f} ms"


def went_wrong(r: dict[str, Any]) -> bool:
    return bool(r["fault_messages"] or r["notes"] or r["restarts"] or r["deaths"] or r.get("error")) or not (
        r["vanish_s"] <= 0.150
    )


def service_soak(
    runs: int, seconds: float, burners: int, web_priority: int, logs: Path | None = None, kernel_workers: int = 0
) -> int:
    logs = logs or Path(tempfile.mkdtemp(prefix="riderlive-soak-"))
    logs.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        workdir = Path(tmp)
        rig = bench_rig(workdir / "soak.toml", 120.0, 1_000_000, soft_start_s=0.3, park_s=0.3)
        print(
            f"service soak: {runs} x {seconds:g} s armed, bench3 at 120 Hz (reply_budget_s {rig.bus.reply_budget_s:g}, "
            f"read every {rig.bus.read_divider} ticks, bus_watchdog_ms {rig.bus.bus_watchdog_ms}), tick SCHED_FIFO 50, "
            f"web SCHED_FIFO {web_priority}, kernel workers {kernel_workers or 'as the host has them'}, "
            f"{burners} normal-priority burners; logs of runs gone wrong in {logs}",
            flush=True,
        )
        print(f"unbound kernel workers at the start: {dict(census())} (service/kworkers.py)", flush=True)
        emu = Emulator(rig, priority=60)
        config = (
            f"[server]\nrealtime_priority = {web_priority}\n"
            f'[tick]\nrate = 120.0\n[security]\ntoken = "{TOKEN}"\n'
            f'[rig]\nfile = "{workdir / "soak.toml"}"\nport = "{emu.port}"\n'
            f"[host]\nkernel_workers_priority = {kernel_workers}\n"
        )
        results: list[dict[str, Any]] = []
        live = LiveServer(config, workdir, token=TOKEN)
        loads: list[float] = []
        try:
            client = httpx.Client(base_url=live.base, headers=AUTH, timeout=10.0)
            frames = Frames(live.ws)
            wait_state(client, {"disarmed"}, 30.0)
            with other_core_busy(runs * (seconds + 60), burners > 0, burners):
                for n in range(runs):
                    first_line, mark, t0 = len(live.log), frames.mark(), time.strftime("%H:%M:%S")
                    try:
                        r = soak_run(client, emu, rig.name, seconds)
                    except (SoakError, httpx.HTTPError) as exc:
                        r = {"fault_messages": [], "notes": [], "restarts": 0, "deaths": 0, "hangs": 0}
                        r |= {"takeovers": 0, "stalls": 0, "vanish_s": math.nan, "error": str(exc)}
                        try:
                            r["last_exit"] = device(client)["supervision"]["last_exit"]
                        except httpx.HTTPError:
                            r["last_exit"] = "the service does not answer"
                    r["gaps"] = frames.gaps(mark)
                    loads.append(os.getloadavg()[0])
                    results.append(r)
                    print(run_line(n + 1, t0, r), flush=True)
                    if went_wrong(r):
                        path = logs / f"run-{n + 1:02d}.log"
                        path.write_text(f"{run_line(n + 1, t0, r)}\n\n" + "".join(live.log[first_line:]))
                        print(f"    its log: {path}", flush=True)
                    if r.get("error") and "arm refused" in str(r["error"]):
                        recover_service(client, rig.name)
            frames.close()
            client.close()
        finally:
            live.stop()
            emu.stop()
            (logs / "serve.log").write_text("".join(live.log))
            warnings = [line.strip() for line in live.log if "warning:" in line]
    return summary(results, warnings, loads, frames.drops, logs)


def recover_service(client: httpx.Client, name: str) -> None:
    """After a refused arm (a tick down): wait up to 120 s for a ticking service, disarmed."""
    deadline = time.perf_counter() + 120.0
    while time.perf_counter() < deadline:
        try:
            if device(client)["supervision"]["up"]:
                recover(client)
                return
        except (SoakError, httpx.HTTPError):
            pass
        time.sleep(0.5)


def run_line(n: int, started: str, r: dict[str, Any]) -> str:
    vanish = "not seen" if r["vanish_s"] != r["vanish_s"] else f"{r['vanish_s'] * 1000:.1f} ms"
    extra = f" last exit: {r['last_exit']}" if r.get("last_exit") else ""
    extra += f" ERROR: {r['error']}" if r.get("error") else ""
    extra += "".join(f" NOTE: {note}" for note in r["notes"])
    return (
        f"  run {n:2d} ({started}): faults {len(r['fault_messages'])} {'; '.join(r['fault_messages'])} "
        f"hangs {r['hangs']} deaths {r['deaths']} restarts {r['restarts']} takeovers {r['takeovers']} "
        f"stalls excused {r['stalls']} ridden-through silences {r.get('armed_ridethroughs', 0)} armed, "
        f"{r.get('stall_ridethroughs', 0) - r.get('armed_ridethroughs', 0)} in the vanish; read failures "
        f"{r.get('read_failures', 0)}/{r.get('reads', 0)}; tick gaps {percentiles(r['gaps'])}; vanish {vanish}{extra}"
    )


def summary(results: list[dict[str, Any]], warnings: list[str], loads: list[float], drops: int, logs: Path) -> int:
    faults = sum(1 for r in results for m in r["fault_messages"] if not m.startswith("tick restarted"))
    hangs = sum(r["hangs"] for r in results)
    ridden = sum(r.get("armed_ridethroughs", 0) for r in results)
    in_vanish = sum(r.get("stall_ridethroughs", 0) for r in results) - ridden
    seen = sorted(r["vanish_s"] * 1000 for r in results if r["vanish_s"] == r["vanish_s"])
    missed = sum(1 for r in results if r["vanish_s"] != r["vanish_s"])
    gaps = [g for r in results for g in r["gaps"]]
    exits = [r["last_exit"] for r in results if r.get("last_exit")]
    wrong = sum(1 for r in results if went_wrong(r))
    print(f"\nserve's start warnings: {warnings or 'none'}")
    print(
        f"{len(results)} runs (load average at their ends {min(loads, default=0):.1f}-{max(loads, default=0):.1f}): "
        f"faults {faults} (target 0; without the stall discount {faults + ridden}: {ridden} silences ridden through "
        f"while armed; {in_vanish} more in the vanish trials, each a fault anyway, its detection later by the "
        "host's share), "
        f"false hangs {hangs} (target 0), deaths {sum(r['deaths'] for r in results)} {exits or ''}, restarts "
        f"{sum(r['restarts'] for r in results)}, warm takeovers {sum(r['takeovers'] for r in results)}, stalls excused "
        f"{sum(r['stalls'] for r in results)}, runs with an error {sum(1 for r in results if r.get('error'))}"
    )
    print(f"tick gaps at a /ws/rider client: {percentiles(gaps)} (client reconnects {drops})")
    if seen:
        print(
            f"vanish detected in median {statistics.median(seen):.1f} ms, max {seen[-1]:.1f} ms (target <= 150), "
            f"over 150 ms {sum(v > 150 for v in seen)}, not seen within {VANISH_WAIT_S:g} s {missed}"
        )
    print(f"runs gone wrong {wrong}: their logs in {logs}")
    ok = faults == 0 and hangs == 0 and not missed and bool(seen) and seen[-1] <= 150.0
    return 0 if ok else 1
