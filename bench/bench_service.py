"""The whole service under load: 100 subscribed clients, a live producer, the other core busy.

    PYTHONPATH=. python bench/bench_service.py --rate 500 --seconds 60 --clients 100

Starts the real ``riderlive serve`` twice on a loopback port: with the tick in its
own process (the design) and, as the baseline, in a thread of the web process
(``tick.isolation = "thread"``). Each run: one producer streams horse frames at
``--producer-rate``; ``--clients`` websocket clients subscribe at ``--client-rate``
(binary, two channels); halfway through, one extra client stops reading. Reports
tick lateness (server histogram), skipped ticks, horse-received -> rider-sent latency
(server histogram), and per-client delivery before and after the stalled client: the
fraction of the ticks that ran (deadlines the tick skipped are not counted) that a
client received.
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import multiprocessing
import os
import re
import socket
import struct
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import msgpack
import orjson
from websockets.asyncio.client import connect

from bench import serving
from bench.serving import burn

ROOT = Path(__file__).resolve().parents[1]
LATENESS = "riderlive_tick_lateness_seconds"
LATENCY = "riderlive_input_to_send_seconds"
COALESCED = "riderlive_ticks_coalesced_total"


def start_server(rate: float, isolation: str, workdir: Path, nice: int) -> tuple[subprocess.Popen[str], int]:
    config = workdir / f"{isolation}.toml"
    config.write_text(
        f'[server]\nlog_level = "warning"\nnice = {nice}\n[tick]\nrate = {rate}\nisolation = "{isolation}"\n'
        "[publish]\nsend_timeout = 2.0\nmax_clients = 1000\n"
    )
    return serving.start_server(config, min_ticks=rate, timeout=30.0)


def cpu_seconds(pid: int) -> float:
    """User + system CPU seconds of one process (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def children(pid: int) -> list[int]:
    try:
        return [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


def histogram(text: str, name: str) -> list[tuple[float, float]]:
    out = []
    for match in re.finditer(rf'^{name}_bucket{{le="([^"]+)"}} (\S+)$', text, re.M):
        out.append((float("inf") if match.group(1) == "+Inf" else float(match.group(1)), float(match.group(2))))
    return out


def delta(after: list[tuple[float, float]], before: list[tuple[float, float]]) -> list[tuple[float, float]]:
    return [(le, a - b) for (le, a), (_, b) in zip(after, before, strict=True)]


def quantile_bound(buckets: list[tuple[float, float]], q: float) -> float:
    """The upper bound of the bucket holding quantile ``q`` (cumulative buckets)."""
    total = buckets[-1][1]
    for le, count in buckets:
        if count >= q * total:
            return le
    return float("inf")


def metric(text: str, name: str) -> float:
    match = re.search(rf"^{name} (\S+)$", text, re.M)
    return float(match.group(1)) if match else 0.0


@dataclass
class ClientStats:
    seqs: list[int] = field(default_factory=list)
    at: list[float] = field(default_factory=list)


def _masked(opcode: int, payload: bytes) -> bytes:
    """A client->server websocket frame (clients must mask)."""
    mask = os.urandom(4)
    body = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
    n = len(payload)
    head = bytes([0x80 | opcode, 0x80 | n]) if n < 126 else bytes([0x80 | opcode, 0xFE]) + struct.pack(">H", n)
    return head + mask + body


class LeanSubscriber(asyncio.Protocol):
    """A minimal websocket client (handshake, frame parser, pong): cheap enough that 100
    of them in one process measure the server, not the client library."""

    def __init__(self, stats: ClientStats, subscribe: bytes) -> None:
        self.stats, self.subscribe = stats, subscribe
        self.buffer = bytearray()
        self.upgraded = False
        self.subscribed = False
        self.transport: asyncio.Transport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        key = base64.b64encode(os.urandom(16)).decode()
        transport.write(
            f"GET /ws/rider HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
            f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n".encode()
        )

    def data_received(self, data: bytes) -> None:
        self.buffer += data
        if not self.upgraded:
            end = self.buffer.find(b"\r\n\r\n")
            if end < 0:
                return
            del self.buffer[: end + 4]
            self.upgraded = True
            assert self.transport is not None
            self.transport.write(_masked(1, self.subscribe))
        buf = self.buffer
        pos = 0
        now = time.perf_counter()
        while len(buf) - pos >= 2:
            opcode, n = buf[pos] & 0x0F, buf[pos + 1] & 0x7F
            head = 2
            if n == 126:
                if len(buf) - pos < 4:
                    break
                n, head = struct.unpack_from(">H", buf, pos + 2)[0], 4
            elif n == 127:
                if len(buf) - pos < 10:
                    break
                n, head = struct.unpack_from(">Q", buf, pos + 2)[0], 10
            if len(buf) - pos < head + n:
                break
            start = pos + head
            if opcode == 2 and self.subscribed:
                self.stats.seqs.append(struct.unpack_from("<Q", buf, start + 8)[0])
                self.stats.at.append(now)
            elif opcode == 1 and b'"subscribed"' in buf[start : start + n]:
                self.subscribed = True
            elif opcode == 9 and self.transport is not None:
                self.transport.write(_masked(10, bytes(buf[start : start + n])))
            pos = start + n
        del buf[:pos]


async def subscriber(port: int, rate: float, stats: ClientStats, stop: asyncio.Event) -> None:
    sub = {"type": "subscribe", "channels": ["lower_back.rz", "head.rz"], "rate": rate, "encoding": "binary"}
    loop = asyncio.get_running_loop()
    transport, _ = await loop.create_connection(lambda: LeanSubscriber(stats, orjson.dumps(sub)), "127.0.0.1", port)
    await stop.wait()
    transport.close()


async def producer(url: str, rate: float, stop: asyncio.Event) -> None:
    async with connect(url + "/ws/horse") as ws:
        await ws.recv()
        t0 = time.perf_counter()
        n = 0
        while not stop.is_set():
            n += 1
            await asyncio.sleep(max(0.0, t0 + n / rate - time.perf_counter()))
            t = time.perf_counter() - t0
            await ws.send(msgpack.packb({"t": t, "values": {"rearPivot.rz": 3.0 * (t % 1.0), "lfHoof.ty": 0.1}}))


def stalled_client(port: int) -> socket.socket:
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.connect(("127.0.0.1", port))
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall(
        f"GET /ws/rider HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n".encode()
    )
    sock.recv(12)
    return sock


def delivery(
    stats: list[ClientStats], start: float, stop: float, decimation: int, skipped: float = 0.0
) -> tuple[float, float]:
    """(worst, mean) fraction of the ticks run in [start, stop) that a client received.

    ``skipped``: deadlines the tick skipped in the window (no tick ran, so no frame
    can be sent: the seq gap is not a delivery loss).
    """
    fractions = []
    for s in stats:
        seqs = [q for q, a in zip(s.seqs, s.at, strict=True) if start <= a < stop]
        if len(seqs) < 2:
            fractions.append(0.0)
            continue
        expected = max(1.0, (seqs[-1] - seqs[0]) // decimation + 1 - skipped / decimation)
        fractions.append(min(1.0, len(seqs) / expected))
    return min(fractions), sum(fractions) / len(fractions)


async def drive(port: int, args: argparse.Namespace, pid: int | None = None) -> dict[str, float]:
    url = f"ws://127.0.0.1:{port}"
    http = f"http://127.0.0.1:{port}"
    stop = asyncio.Event()
    stats = [ClientStats() for _ in range(args.clients)]
    tasks = [asyncio.create_task(subscriber(port, args.client_rate, s, stop)) for s in stats]
    tasks.append(asyncio.create_task(producer(url, args.producer_rate, stop)))
    await asyncio.sleep(2.0)  # everyone connected and subscribed
    async with httpx.AsyncClient(timeout=60.0) as client:
        before = (await client.get(http + "/metrics")).text
        pids = [pid, *children(pid)] if pid else []
        cpu_before = [cpu_seconds(p) for p in pids]
        t_start = time.perf_counter()
        await asyncio.sleep(args.seconds / 2)
        middle = (await client.get(http + "/metrics")).text
        stall = stalled_client(port)
        t_stall = time.perf_counter()
        await asyncio.sleep(0.5)
        settled = (await client.get(http + "/metrics")).text
        await asyncio.sleep(args.seconds / 2 - 0.5)
        t_end = time.perf_counter()
        cpu_after = [cpu_seconds(p) for p in pids]
        after = (await client.get(http + "/metrics")).text
        state = (await client.get(http + "/api/state")).json()
    sent = sorted(c["sent"] for c in state["clients"])
    dropped = sorted(c["dropped"] for c in state["clients"])
    if sent:
        print(f"  server side: sent per client {sent[0]}..{sent[-1]}, dropped {dropped[0]}..{dropped[-1]}", flush=True)
    stop.set()
    for task in tasks:
        task.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
    stall.close()
    decimation = max(1, round(args.rate / args.client_rate))
    lateness = delta(histogram(after, LATENESS), histogram(before, LATENESS))
    latency = delta(histogram(after, LATENCY), histogram(before, LATENCY))
    skipped = "riderlive_tick_skipped_total"
    worst_before, mean_before = delivery(
        stats, t_start, t_stall, decimation, metric(middle, skipped) - metric(before, skipped)
    )
    worst_after, mean_after = delivery(
        stats, t_stall + 0.5, t_end, decimation, metric(after, skipped) - metric(settled, skipped)
    )
    return {
        "lateness_p99_bound_ms": quantile_bound(lateness, 0.99) * 1e3,
        "lateness_max_ms": metric(after, "riderlive_tick_lateness_max_seconds") * 1e3,
        "skipped": metric(after, "riderlive_tick_skipped_total") - metric(before, "riderlive_tick_skipped_total"),
        "latency_p99_bound_ms": quantile_bound(latency, 0.99) * 1e3,
        "latency_p50_bound_ms": quantile_bound(latency, 0.5) * 1e3,
        "worst_before": worst_before,
        "mean_before": mean_before,
        "worst_after": worst_after,
        "mean_after": mean_after,
        "cut_off": metric(after, "riderlive_clients_cut_off_total"),
        "coalesced": metric(after, COALESCED) - metric(before, COALESCED),
        "web_cpu": (cpu_after[0] - cpu_before[0]) / (t_end - t_start) if pids else float("nan"),
        "tick_cpu": sum(a - b for a, b in zip(cpu_after[1:], cpu_before[1:], strict=True)) / (t_end - t_start)
        if pids
        else float("nan"),
    }


def run(isolation: str, args: argparse.Namespace, workdir: Path) -> dict[str, float]:
    proc, port = start_server(args.rate, isolation, workdir, args.nice)
    try:
        return asyncio.run(drive(port, args, proc.pid))
    finally:
        proc.terminate()
        proc.wait(20)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rate", type=float, default=500.0, help="tick rate, Hz")
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--baseline-seconds", type=float, help="default: --seconds")
    parser.add_argument("--clients", type=int, default=100)
    parser.add_argument("--client-rate", type=float, default=120.0)
    parser.add_argument("--producer-rate", type=float, default=120.0)
    parser.add_argument("--no-burner", action="store_true")
    parser.add_argument("--nice", type=int, default=0, help="server.nice of the service (e.g. -10)")
    args = parser.parse_args()
    workdir = Path(tempfile.mkdtemp(prefix="bench-service-"))
    baseline_args = argparse.Namespace(**{**vars(args), "seconds": args.baseline_seconds or args.seconds})
    burner = None
    if not args.no_burner:
        total = args.seconds + baseline_args.seconds + 60
        burner = multiprocessing.get_context("spawn").Process(target=burn, args=(time.perf_counter() + total,))
        burner.start()
    try:
        design = run("process", args, workdir)
        baseline = run("thread", baseline_args, workdir)
    finally:
        if burner is not None:
            burner.terminate()
            burner.join()
    period_ms = 1e3 / args.rate
    print(
        f"tick {args.rate:g} Hz, {args.clients} clients at {args.client_rate:g} Hz, producer at "
        f"{args.producer_rate:g} Hz, other core busy: {not args.no_burner}, {args.seconds:g} s"
    )
    rows = (
        ("tick lateness p99 <= (ms)", "lateness_p99_bound_ms", "{:.3f}"),
        ("tick lateness max (ms)", "lateness_max_ms", "{:.3f}"),
        ("skipped ticks", "skipped", "{:.0f}"),
        ("input->send p50 <= (ms)", "latency_p50_bound_ms", "{:.1f}"),
        ("input->send p99 <= (ms)", "latency_p99_bound_ms", "{:.1f}"),
        ("worst client delivery, before stall", "worst_before", "{:.3f}"),
        ("mean client delivery, before stall", "mean_before", "{:.3f}"),
        ("worst client delivery, stall", "worst_after", "{:.3f}"),
        ("mean client delivery, stall", "mean_after", "{:.3f}"),
        ("stalled clients cut off", "cut_off", "{:.0f}"),
        ("ticks not sent (web process 0.25 s behind)", "coalesced", "{:.0f}"),
        ("web process CPU (cores)", "web_cpu", "{:.2f}"),
        ("tick process(es) CPU (cores)", "tick_cpu", "{:.2f}"),
    )
    print(f"{'':38}{'process (design)':>18}{'thread (baseline)':>19}")
    for label, key, fmt in rows:
        print(f"{label:38}{fmt.format(design[key]):>18}{fmt.format(baseline[key]):>19}")
    ratio = baseline["lateness_max_ms"] / max(design["lateness_max_ms"], 1e-6)
    print(f"tick lateness max ratio baseline/design: {ratio:.1f}x")
    checks = {
        "lateness p99 <= 0.5 ms": design["lateness_p99_bound_ms"] <= 0.5,
        "lateness max <= 3 ms": design["lateness_max_ms"] <= 3.0,
        "no skipped tick": design["skipped"] == 0,
        f"input->send p99 <= {period_ms + 1:.1f} ms": design["latency_p99_bound_ms"] <= period_ms + 1.0,
        "every client >= 99.9 %": design["worst_before"] >= 0.999,
        "stalled client changes no rate (>= 99.9 %)": design["worst_after"] >= 0.999,
    }
    for check, ok in checks.items():
        print(f"  {check}: {'met' if ok else 'NOT met'}")


if __name__ == "__main__":
    main()
