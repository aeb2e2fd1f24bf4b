"""``riderlive rig --drive --arm`` (the service's tick loop in the CLI's process): its stops, timed.

    PYTHONPATH=$PWD .venv/bin/python bench/bench_rig_drive.py [--trials 5] [--cases estop kill guardian hang_kill]

The CLI drives bench3 (park_s 0.5 s, 100 ticks/s) on the emulated bus (a child process,
wire timing, SCHED_FIFO as the servos it stands for), trotting, both cores busy unless
``--idle``. Per trial, once it runs:

- ``estop``: SIGINT of the CLI (an e-stop: torque off at once, read back, exit 130);
- ``kill``: SIGKILL of the CLI (its guardian parks the rig);
- ``guardian``: SIGKILL of the guardian (its standby watches; the tick parks the rig, exit 1);
- ``hang_kill``: SIGSTOP of the CLI, then SIGKILL of its guardian (the standby takes over,
  finds the tick hung after the 0.1 s threshold, kills it and parks).

Measured from the signal, on the emulator's clock: the first park goal (not for ``estop``),
the torque-off broadcast, goal writes after it (target 0). Targets: e-stop torque off
<= one tick + 21 ms (the test's bound); a park's torque off <= park_s + 200 ms after
whatever found the failure (``hang_kill``: + the threshold).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench.rig_fixtures import Emulator, bench_rig, is_goal_write, other_core_busy, torque_offs

ROOT = Path(__file__).resolve().parents[1]
PARK_S = 0.5
TARGETS_MS = {"estop": (None, 10 + 21), "kill": (200, 700), "guardian": (200, 800), "hang_kill": (800, 1300)}
"""Case -> (first park goal, torque off) targets in ms from the signal."""


def start(path: Path, port: str, root: Path = ROOT) -> tuple[subprocess.Popen[str], int, int]:
    """The CLI of the checkout ``root``, once its rig runs; with its guardian's and standby's pids
    (0: it said none)."""
    cli = subprocess.Popen(
        [sys.executable, "-m", "riderlive", "rig", str(path), "--port", port, "--drive", "120", "--arm"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "PYTHONPATH": str(root), "PYTHONUNBUFFERED": "1"},
        cwd=root,  # `-m` puts the working directory first on sys.path
    )
    assert cli.stdout is not None
    pids = (0, 0)
    for line in cli.stdout:
        if m := re.search(r"guardian (\d+) watches; standby (\d+)", line):
            pids = (int(m.group(1)), int(m.group(2)))
        if "soft_start -> running" in line:
            return cli, *pids
    raise RuntimeError(f"the CLI never ran: exit {cli.wait(10)}")


def trial(emu: Emulator, path: Path, case: str, root: Path = ROOT) -> dict[str, float]:
    cli, guardian, standby = start(path, emu.port, root)
    time.sleep(0.5)  # half a second of running goals before the signal (a bench, not a test)
    emu.ask("arrivals")
    try:
        at = time.perf_counter()
        if case == "estop":
            cli.send_signal(signal.SIGINT)
        elif case == "kill":
            cli.kill()
        elif case == "guardian":
            os.kill(guardian, signal.SIGKILL)
        else:
            cli.send_signal(signal.SIGSTOP)
            os.kill(guardian, signal.SIGKILL)
        deadline = time.perf_counter() + 15.0
        while any(emu.ask(("torque", [1, 2, 3]))) and time.perf_counter() < deadline:
            time.sleep(0.02)
        time.sleep(0.1)
        packets = [(t, raw) for t, raw in emu.ask("arrivals") if t > at]
        off = torque_offs(packets)
        goals = [t for t, raw in packets if is_goal_write(raw)]
        return {
            "first_goal": goals[0] - at if goals and case != "estop" else float("nan"),
            "torque_off": off[0] - at if off else float("nan"),
            "after_off": float(sum(t > off[0] for t in goals)) if off else float("nan"),
        }
    finally:
        for pid in (guardian, standby):
            if pid <= 0:  # none said (main's CLI): kill(0) would be this process group
                continue
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        if cli.poll() is None:
            cli.kill()
        cli.communicate(timeout=30)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=5)
    parser.add_argument("--cases", nargs="+", default=list(TARGETS_MS))
    parser.add_argument("--idle", action="store_true", help="do not keep both cores busy")
    parser.add_argument("--root", type=Path, default=ROOT, help="the checkout whose CLI runs (a baseline: main's)")
    args = parser.parse_args()
    ok = True
    with tempfile.TemporaryDirectory() as tmp, other_core_busy(7200, not args.idle, burners=2):
        rig = bench_rig(Path(tmp) / "bench3.toml", 100.0, park_s=PARK_S, soft_start_s=0.3, bus_watchdog_ms=600)
        emu = Emulator(rig, priority=60)
        try:
            host = "quiet" if args.idle else "loaded (two burners)"
            print(f"{args.root}: host {host}; load {os.getloadavg()[0]:.1f}")
            for case in args.cases:
                results = [trial(emu, Path(tmp) / "bench3.toml", case, args.root) for _ in range(args.trials)]
                goal_target, off_target = TARGETS_MS[case]
                off = [r["torque_off"] * 1000 for r in results]
                after = sum(int(r["after_off"]) for r in results if r["after_off"] == r["after_off"])
                line = f"{case:9s} x{args.trials}: torque off median {statistics.median(off):6.1f}"
                line += f" max {max(off):6.1f} ms"
                line += f" (<= {off_target})"
                ok &= max(off) <= off_target and after == 0
                if goal_target is not None:
                    first = [r["first_goal"] * 1000 for r in results]
                    line += f"; first park goal median {statistics.median(first):6.1f} max {max(first):6.1f} ms"
                    line += f" (<= {goal_target})"
                    ok &= max(first) <= goal_target
                print(f"{line}; goal writes after torque off {after} (0)", flush=True)
        finally:
            emu.stop()
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
