"""E-stop through the real service: REST request to torque off on the wire, and no goal after.

    PYTHONPATH=$PWD .venv/bin/python bench/bench_estop.py [--trials 200] [--rates 120 500] [--idle] [--web-priority 10]

``riderlive serve`` runs with a 3-servo rig (config/rigs/bench3.toml fitted to the rate)
on the emulated bus (a child process, wire timing, SCHED_FIFO like the servos it stands
for), the tick at SCHED_FIFO where allowed, the web process (where REST e-stops arrive) at
SCHED_FIFO 10 (``server.realtime_priority``, as docs/hardware.md asks for a rig near
people; ``--web-priority 0`` for normal scheduling), and the other core busy. Each trial: arm,
run a random 50-150 ms, ``POST /api/estop``, reset. Measured, per trial:

- handler -> wire: from the moment the service's handler had the request
  (``received_at`` in the answer) to the torque-off broadcast fully arrived at the
  emulator. Target: max <= 1 tick + 1 ms (issue 10).
- handler -> written: the same to the moment the tick's write of the torque-off returned
  (the device's e-stop record). On a USB adapter that write hands the packet to the USB
  host controller at once; on the pty the kernel's tty worker (a normal-priority kernel
  thread, competing with the busy core) must still carry it to the emulator, which the
  split below shows as "written -> arrived".
- client -> wire: from this process sending the request (HTTP included), for reference.
- goal writes after the request: goal SYNC_WRITEs that arrived after the torque-off
  (target 0; the latch's gate makes it structural); goal writes that *began* after the
  request's arrival (target 0: the tick's e-stop record says when its last goal write
  began, ``last_goal_at``, checked against the emulator: the last goal packet that
  arrived before the torque-off is that write's goals); and, for reference, goal packets
  that arrived after ``received_at`` at all (writes begun before it, still in flight on
  the pty). ``received_at`` is the first thing the outermost ASGI layer does with an
  e-stop (service/estop_first.py), ``latched_at`` right after it.
"""

from __future__ import annotations

import argparse
import random
import statistics
import sys
import tempfile
import time
from pathlib import Path

import httpx

from bench.rig_fixtures import Emulator, bench_rig, decode_goals, is_goal_write, other_core_busy, torque_offs
from riderlive.dynamixel.servo_map import deg_to_pulses
from riderlive.service.kworkers import census
from tests.service.live_server import LiveServer

START_TIMEOUT_S = 120.0
"""A saturated host (load 20-30) can take over 30 s to import and start the service."""

TOKEN = "bench-token-1"
AUTH = {"Authorization": f"Bearer {TOKEN}"}


def state(live: LiveServer) -> str:
    devices = live.get("/api/devices", headers=AUTH).json()["devices"]
    return str(devices[0]["state"]) if devices else "none"


def stop_record(live: LiveServer) -> dict[str, float | None]:
    """The device's last e-stop record: requested, acted on by the tick, written (perf_counter s)."""
    devices = live.get("/api/devices", headers=AUTH).json()["devices"]
    return dict(devices[0]["estop"] or {})


def last_goals(live: LiveServer) -> dict[int, int]:
    """The rig's last goals sent (servo id -> pulses), from the service's status."""
    rig = live.get("/api/state", headers=AUTH).json()["tick"]["rig"]
    return {servo["id"]: deg_to_pulses(servo["goal_deg"]) for servo in rig["servos"]}


def wait_state(live: LiveServer, wanted: str, timeout: float = 10.0) -> None:
    deadline = time.perf_counter() + timeout
    while (now := state(live)) != wanted:
        if time.perf_counter() > deadline:
            device = live.get("/api/devices", headers=AUTH).json()["devices"][0]
            raise SystemExit(f"rig is {now}, wanted {wanted}: {device.get('detail')!r}, fault {device.get('fault')!r}")
        time.sleep(0.01)


def arm(client: httpx.Client, name: str, live: LiveServer, timeout: float = 60.0) -> None:
    """Arm, retrying while the service is not ready (the guardian starting, a tick restart)."""
    deadline = time.perf_counter() + timeout
    while (answer := client.post("/api/arm", json={"device": name})).status_code != 200:
        if time.perf_counter() > deadline:
            log = "".join(live.log[-40:])
            raise SystemExit(f"arm refused: {answer.text}\nthe service's last lines:\n{log}")
        time.sleep(0.1)


def running(client: httpx.Client, name: str, live: LiveServer, retries: list[str]) -> None:
    """Armed and running. On a loaded host the tick may park an armed rig by itself (it
    lost sight of the guardian: docs/hardware.md) or a start may fault: that is noted in
    ``retries`` with the reason and the start tried again (at most 5 times)."""
    for _ in range(5):
        if state(live) in ("fault", "estop"):
            client.post("/api/reset")
        arm(client, name, live)
        deadline = time.perf_counter() + 10.0
        while (now := state(live)) not in ("running", "parked", "parking", "disarmed", "fault"):
            if time.perf_counter() > deadline:
                break
            time.sleep(0.01)
        if now == "running":
            return
        device = live.get("/api/devices", headers=AUTH).json()["devices"][0]
        retries.append(f"{now}: {device.get('detail')!r}")
        print(f"  (the rig went {now}, not running: {device.get('detail')!r}; arming again)", flush=True)
        deadline = time.perf_counter() + 10.0
        while state(live) == "parking" and time.perf_counter() < deadline:  # then parked or disarmed
            time.sleep(0.01)
    raise SystemExit("the rig could not be kept running")


def run(rate: float, trials: int, workdir: Path, web_priority: int, kernel_workers: int = 0) -> dict[str, list[float]]:
    baud = 1_000_000 if rate <= 200 else 4_000_000
    changes = {"soft_start_s": 0.1, "park_s": 0.2, "bus_watchdog_ms": 200, "reply_budget_s": 0.5}  # e-stops, not faults
    rig = bench_rig(workdir / f"bench{rate:g}.toml", rate, baud, **changes)
    emu = Emulator(rig, priority=60)
    config = (
        f"[server]\nrealtime_priority = {web_priority}\n"
        f'[tick]\nrate = {rate}\n[security]\ntoken = "{TOKEN}"\n'
        f'[rig]\nfile = "{workdir / f"bench{rate:g}.toml"}"\nport = "{emu.port}"\n'
        f"[host]\nkernel_workers_priority = {kernel_workers}\n"
    )
    for attempt in range(3):  # a saturated machine can take > 30 s to import the service
        try:
            live = LiveServer(config, workdir, token=TOKEN, start_timeout_s=START_TIMEOUT_S)
            break
        except RuntimeError as exc:
            if attempt == 2:
                emu.stop()
                raise
            print(f"  (the service did not start, retrying: {str(exc)[-300:]})", flush=True)
    out: dict[str, list[float]] = {
        "handler": [],
        "latch": [],
        "client": [],
        "after_off": [],
        "after_request": [],
        "began_after": [],
        "unmatched": [],
        "acted": [],
        "written": [],
        "arrived": [],
        "host": [],
    }
    retries: list[str] = []
    try:
        client = httpx.Client(base_url=live.base, headers=AUTH, timeout=10.0)
        wait_state(live, "disarmed", 30.0)
        emu.ask("arrivals")
        for n in range(trials):
            while True:
                running(client, rig.name, live, retries)
                time.sleep(random.uniform(0.05, 0.15))
                if state(live) == "running":
                    break
                retries.append("parked by itself before the e-stop")
            sent = time.perf_counter()
            answer = client.post("/api/estop").json()
            wait_state(live, "estop")
            packets = emu.ask("arrivals")
            offs = [t for t in torque_offs(packets) if t > sent]
            if not offs:
                raise SystemExit(f"trial {n}: no torque-off reached the emulator")
            off = offs[0]
            received = answer["received_at"]
            out["handler"].append(off - received)
            out["latch"].append(off - answer["latched_at"])
            out["client"].append(off - sent)
            record = stop_record(live)
            acted, written = record.get("acted_at"), record.get("off_written_at")
            if isinstance(acted, float) and isinstance(written, float):
                out["acted"].append(acted - answer["latched_at"])
                out["written"].append(written - acted)
                out["arrived"].append(off - written)
                out["host"].append(written - received)
            goals = [t for t, raw in packets if is_goal_write(raw)]
            out["after_off"].append(sum(1 for t in goals if t > off))
            out["after_request"].append(sum(1 for t in goals if t > received))
            began = record.get("last_goal_at")
            out["began_after"].append(float(isinstance(began, float) and began > received))
            before_off = [raw for t, raw in packets if is_goal_write(raw) and t < off]
            out["unmatched"].append(float(bool(before_off) and decode_goals(before_off[-1]) != last_goals(live)))
            assert client.post("/api/reset").status_code == 200
            wait_state(live, "disarmed")
            if (n + 1) % 25 == 0:  # a partial figure, should a long run have to be stopped
                print(
                    f"  after {n + 1} trials: goal writes begun after the arrival {sum(out['began_after']):.0f}, "
                    f"after the torque-off {sum(out['after_off']):.0f}; handler -> wire {summary(out['handler'])}",
                    flush=True,
                )
        supervision = live.get("/api/devices", headers=AUTH).json()["supervision"]
        out["restarts"] = [float(supervision["restarts"])]
        out["retries"] = [float(len(retries))]
        client.close()
    finally:
        live.stop()
        emu.stop()
    return out


def summary(values: list[float]) -> str:
    ms = sorted(v * 1000 for v in values)
    p99 = ms[min(len(ms) - 1, int(0.99 * len(ms)))]
    return f"median {statistics.median(ms):6.2f}  p99 {p99:6.2f}  max {ms[-1]:6.2f} ms"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=200)
    parser.add_argument("--rates", type=float, nargs="+", default=[120.0, 500.0])
    parser.add_argument("--idle", action="store_true", help="do not keep the other core busy")
    parser.add_argument(
        "--web-priority", type=int, default=10, help="server.realtime_priority (SCHED_FIFO of the web process; 0: off)"
    )
    parser.add_argument(
        "--kernel-workers",
        type=int,
        default=0,
        help="host.kernel_workers_priority: unbound kernel workers at this SCHED_FIFO (0: off; service/kworkers.py)",
    )
    args = parser.parse_args()
    sys.setswitchinterval(0.0005)
    ok = True
    with tempfile.TemporaryDirectory() as tmp, other_core_busy(3600, not args.idle):
        for rate in args.rates:
            r = run(rate, args.trials, Path(tmp), args.web_priority, args.kernel_workers)
            limit = 1000.0 / rate + 1.0
            worst = max(r["handler"]) * 1000
            after = sum(r["after_off"])
            began_after, unmatched = sum(r["began_after"]), sum(r["unmatched"])
            ok &= worst <= limit and after == 0 and began_after == 0 and unmatched == 0
            busy = not args.idle
            print(
                f"\n{rate:g} ticks/s, {args.trials} e-stops, other core busy: {busy}, web process at SCHED_FIFO "
                f"{args.web_priority or 'off'}, kernel workers {args.kernel_workers or 'as the host has them'} "
                f"(target: max <= {limit:.2f} ms)"
            )
            print(f"  unbound kernel workers at the end: {dict(census())} (service/kworkers.py)")
            print(f"  handler -> torque off on the wire  {summary(r['handler'])}")
            print(f"  latched -> torque off on the wire  {summary(r['latch'])}")
            print(f"  client  -> torque off on the wire  {summary(r['client'])}   (HTTP included)")
            print(f"  handler -> torque off written       {summary(r['host'])}   (the host's write returned)")
            print("  where the latched -> wire time goes:")
            print(f"    latched -> the tick acts          {summary(r['acted'])}")
            print(f"    acts -> torque off written        {summary(r['written'])}")
            print(f"    written -> arrived at the servos  {summary(r['arrived'])}")
            print(f"  tick restarts by the supervisor during the run (a hung or dead tick): {r['restarts'][0]:.0f}")
            print(f"  trials started again (the rig parked itself or faulted before the e-stop): {r['retries'][0]:.0f}")
            print(
                f"  goal writes after the torque-off: {after} (target 0); that began after the request's "
                f"arrival: {began_after:.0f} (target 0; the last goal on the wire was not the tick's last: "
                f"{unmatched:.0f}); arriving after it, begun before (in flight): {sum(r['after_request'])} in "
                f"{sum(1 for x in r['after_request'] if x)} trials"
            )
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
