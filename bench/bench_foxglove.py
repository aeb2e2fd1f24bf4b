"""``serve --foxglove``: delivery of the 120 Hz rider to a Foxglove client, and the web process's CPU.

    PYTHONPATH=. .venv/bin/python bench/bench_foxglove.py [--seconds 30] [--burners 1]

One real ``riderlive serve`` (tick 120 Hz, the procedural horse, ``[foxglove] port = 0``)
and ``--burners`` busy processes (default 1: the other core of a 2-core machine). Three
phases of ``--seconds`` each, in one run:

1. a Foxglove client (tests/service/foxglove_client.py, written from the protocol spec)
   subscribed to ``/rider/joints``: delivery = distinct ``seq`` received / records made in
   the ``seq`` span (the span less the ticks the tick skipped, ``counters.skipped``);
2. a ``/ws/rider`` client (JSON, every rider channel): the same delivery by ``seq``;
3. no client (the baseline).

The web process's CPU (utime + stime of ``/proc/PID/stat``) is printed for each phase and
the Foxglove phase's as a ratio against ``/ws/rider``'s.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx
from websockets.sync.client import connect

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.serving import busy_cores, start_server
from tests.service.foxglove_client import FoxgloveClient

CONFIG = """
[tick]
rate = 120.0
[foxglove]
port = 0
"""


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def skipped(port: int) -> int:
    """Ticks the tick skipped so far (a late tick skips deadlines: their ``seq`` never exists)."""
    return int(httpx.get(f"http://127.0.0.1:{port}/api/state", timeout=5).json()["counters"]["skipped"])


def delivery(seqs: list[int], never: int) -> tuple[float, int, int]:
    """Fraction of the records made in the seq span that arrived (``never``: ticks skipped in it),
    distinct received, records made."""
    if len(seqs) < 2:
        return 0.0, len(seqs), 0
    made = max(seqs) - min(seqs) + 1 - never
    distinct = len(set(seqs))
    return distinct / made, distinct, made


def foxglove_phase(port: int, fox_port: int, seconds: float, pid: int) -> tuple[float, tuple[float, int, int]]:
    client = FoxgloveClient(fox_port)
    client.subscribe("/rider/joints")
    time.sleep(1.0)  # subscribed and flowing
    start_count, skipped0 = len(client.received["/rider/joints"]), skipped(port)
    cpu0, t0 = cpu_seconds(pid), time.perf_counter()
    time.sleep(seconds)
    cpu = (cpu_seconds(pid) - cpu0) / (time.perf_counter() - t0)
    messages = client.received["/rider/joints"][start_count:]
    never = skipped(port) - skipped0
    client.close()
    return cpu, delivery([json.loads(data)["seq"] for _, data, _ in messages], never)


def ws_rider_phase(port: int, seconds: float, pid: int) -> tuple[float, tuple[float, int, int]]:
    seqs: list[int] = []
    counting = threading.Event()
    with connect(f"ws://127.0.0.1:{port}/ws/rider", max_size=None) as ws:
        ws.recv(timeout=5)  # hello
        ws.send(json.dumps({"type": "subscribe", "encoding": "json"}))

        def read() -> None:
            try:
                for message in ws:
                    obj = json.loads(message)
                    if obj.get("type") == "frame" and counting.is_set():
                        seqs.append(obj["seq"])
            except Exception as exc:  # the connection closed: say why
                print(f"/ws/rider reader stopped: {exc!r}", file=sys.stderr)

        threading.Thread(target=read, daemon=True).start()
        time.sleep(1.0)
        skipped0 = skipped(port)
        counting.set()
        cpu0, t0 = cpu_seconds(pid), time.perf_counter()
        time.sleep(seconds)
        cpu = (cpu_seconds(pid) - cpu0) / (time.perf_counter() - t0)
        counting.clear()
        never = skipped(port) - skipped0
    return cpu, delivery(seqs, never)


def idle_phase(seconds: float, pid: int) -> float:
    cpu0, t0 = cpu_seconds(pid), time.perf_counter()
    time.sleep(seconds)
    return (cpu_seconds(pid) - cpu0) / (time.perf_counter() - t0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--burners", type=int, default=1, help="busy processes beside the service (0: quiet)")
    args = parser.parse_args()
    workdir = Path(tempfile.mkdtemp(prefix="bench-foxglove-"))
    (workdir / "service.toml").write_text(CONFIG)
    proc, port = start_server(workdir / "service.toml")
    assert proc.stderr is not None
    fox_port = 0
    for line in proc.stderr:
        match = re.search(r"Foxglove WebSocket on port (\d+)", line)
        if match:
            fox_port = int(match.group(1))
            break
    threading.Thread(target=lambda: [None for _ in proc.stderr or ()], daemon=True).start()  # keep the pipe drained
    total = 3 * args.seconds + 10.0
    try:
        with busy_cores(args.burners, total) as load:
            fox_cpu, (fox_rate, fox_got, fox_span) = foxglove_phase(port, fox_port, args.seconds, proc.pid)
            ws_cpu, (ws_rate, ws_got, ws_span) = ws_rider_phase(port, args.seconds, proc.pid)
            idle_cpu = idle_phase(args.seconds, proc.pid)
    finally:
        proc.terminate()
        proc.wait(30)
    print(f"bench_foxglove: tick 120 Hz, {args.seconds:g} s per phase, {load}, {os.cpu_count()} CPUs")
    print(f"  Foxglove /rider/joints: {fox_got}/{fox_span} records delivered = {100 * fox_rate:.3f} %")
    print(f"  /ws/rider (JSON):       {ws_got}/{ws_span} records delivered = {100 * ws_rate:.3f} %")
    print(
        f"  web process CPU: Foxglove {100 * fox_cpu:.1f} %, /ws/rider {100 * ws_cpu:.1f} %, "
        f"no client {100 * idle_cpu:.1f} % of a core"
    )
    extra_fox, extra_ws = fox_cpu - idle_cpu, ws_cpu - idle_cpu
    ratio = extra_fox / extra_ws if extra_ws > 0 else float("nan")
    print(f"  a client's cost over no client: Foxglove {100 * extra_fox:.1f} %, /ws/rider {100 * extra_ws:.1f} % "
          f"(ratio {ratio:.2f})")  # fmt: skip
    print(f"  target: Foxglove delivery >= 99.9 %: {'met' if fox_rate >= 0.999 else 'NOT met'}")
    print(f"  load average over the run: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
