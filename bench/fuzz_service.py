"""Hostile clients against the real service: nothing they send may crash, poison, freeze or go uncounted.

    PYTHONPATH=. python bench/fuzz_service.py --messages 1000000

Starts the real ``riderlive serve`` (120 Hz; the other core busy unless ``--no-burner``)
and, at once:

- a clean producer (priority 1000) streams a moving horse; a clean reader takes every
  frame of ``/ws/rider`` and checks each rider value is finite and inside its plausible
  range (``riderlive.ranges``), that the rider never stays frozen for :data:`FROZEN` s
  while a horse moves, and counts the ticks it missed (its delivery ratio);
- ``--connections`` hostile connections to ``/ws/horse`` and ``/ws/rider`` and a REST
  client send ``--messages`` generated messages (:func:`hostile`): malformed, non-object,
  wrong types, NaN and infinities (msgpack), values out of range, unknown channels,
  clock jumps, bad hellos and subscriptions, oversize text (bytes, not characters),
  16 MB messages, deep nesting, bad REST bodies, and valid messages in between.

At the end: the server and its tick are alive, no ``internal_error``, and every reject
the clients saw (error messages by reason, 1009 closes, REST 4xx by status) equals
what the service counted in ``/metrics``. The same generator runs, much smaller, in
``tests/service/test_fuzz.py``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import multiprocessing
import random
import re
import subprocess
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import msgpack
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed

from bench.serving import busy_cores, start_server
from riderlive.channels import HORSE_NAMES, RIDER_NAMES
from riderlive.ranges import DEFAULT_RANGES

CONFIG = """
[server]
log_level = "warning"
[tick]
rate = 120.0
realtime_priority = false
[input]
max_rate = 1000000.0
max_errors = 1000000000
[publish]
send_timeout = 5.0
max_clients = 1000
"""
FROZEN = 1.0
"""Seconds of identical rider frames, while a horse moves, that count as frozen: longer than
``input.hold`` (0.25 s; 0.5 s in the tests), for which a late input's newest frame is held."""

# -- the generator -----------------------------------------------------------------------

Message = tuple[str, Any]
"""("horse" | "rider", str or bytes) or ("rest", (method, path, body bytes))."""

NAMES = [*HORSE_NAMES, "tail.rz", "", "x" * 300, "../etc", "lfHoof", "lfHoof.tx.ty", "\u00e9.rz", "root.ry"]
EXTREMES = [1e308, -1e308, 1e300, 5e-324, 1e6, -1e6, 91.0, 2**63, 0.0, -0.0, 1e-300]
NON_FINITE = [math.nan, math.inf, -math.inf]
JUNK_VALUES = ["high", None, True, [], {}, [1.0], {"a": 1}, "NaN", "1e400"]
LITERALS = ["NaN", "Infinity", "-Infinity", "1e400", '"x"', "[]", "{}", "null", "true", "-1", "1e300"]


OVERSIZE = [
    json.dumps({"t": 1.0, "values": {}, "pad": "x" * 70000}),
    json.dumps({"t": 1.0, "values": {}, "pad": "\u00e9" * 40000}, ensure_ascii=False),  # 40 k characters, 80 kB
]
DEEP: list[str | bytes] = [
    *("[" * depth + "]" * depth for depth in (100, 2000, 20000)),
    *(b"\x91" * depth + b"\xc0" for depth in (100, 2000, 20000)),
]
HUGE = b"\x00" * (16 << 20)


def _packed(obj: Any) -> bytes:
    packed: bytes = msgpack.packb(obj, use_bin_type=True)
    return packed


def _text(obj: Any) -> str:
    return json.dumps(obj)


class Hostile:
    """A seeded generator of hostile messages; each connection keeps its own producer clock."""

    def __init__(self, seed: int) -> None:
        self.rng = random.Random(seed)
        self.t = 0.0

    def _clock(self) -> float:
        r = self.rng.random()
        if r < 0.02:
            self.t = self.rng.choice([0.0, -5.0, self.t - 100.0, self.t + 1e4, 1.7e9, 1e10, -1e10])
        elif r < 0.03:
            return self.rng.choice([1e11, -1e300, 1e300])  # out of range, not kept
        else:
            self.t += self.rng.uniform(0.0, 0.02)
        return self.t

    def _plausible(self) -> dict[str, float]:
        names = self.rng.sample(HORSE_NAMES, self.rng.randint(0, len(HORSE_NAMES)))
        return {name: self.rng.uniform(-1.5, 1.5) for name in names}  # inside every horse range

    def horse(self) -> str | bytes:
        rng = self.rng
        kind = rng.randrange(16)
        if kind <= 3:  # valid frames, by name (JSON or msgpack) or by position
            frame: dict[str, Any] = {"t": self._clock(), "values": self._plausible()}
            if kind == 3:
                frame = {"t": self._clock(), "v": [rng.uniform(-1, 1) for _ in HORSE_NAMES]}
            return _packed(frame) if kind == 2 else _text(frame)
        if kind == 4:  # out of range
            return _text({"t": self._clock(), "values": {rng.choice(HORSE_NAMES): rng.choice(EXTREMES)}})
        if kind == 5:  # non-finite, which only msgpack can carry
            key = rng.choice(["t", "value"])
            bad = rng.choice(NON_FINITE)
            frame = {"t": bad, "values": {}} if key == "t" else {"t": self._clock(), "values": {"lfHoof.ty": bad}}
            return _packed(frame)
        if kind == 6:  # wrong types and unknown channels
            values = {rng.choice(NAMES): rng.choice([*JUNK_VALUES, 1.0])}
            return _text({"t": rng.choice([self._clock(), "soon", None, [1]]), "values": values})
        if kind == 7:  # a bad or a fine hello
            hello: dict[str, Any] = {"type": "hello"}
            field_name = rng.choice(["name", "priority", "length_scale", "channels"])
            bad_hellos: dict[str, list[Any]] = {
                "name": ["", "x" * 80, 12, None, f"fuzz-{rng.randrange(10**6)}"],
                "priority": [10**9, -(10**9), "high", True, 1.5, rng.randint(-1000, 0)],
                "length_scale": [9.9e8, 0, -1, 1e-9, "m", True, rng.uniform(0.01, 100.0)],
                "channels": [[], ["lfHoof.tx", "lfHoof.tx"], ["nope"], "lfHoof.tx", list(HORSE_NAMES)],
            }
            hello[field_name] = rng.choice(bad_hellos[field_name])
            if field_name == "length_scale" and isinstance(hello[field_name], float) and rng.random() < 0.5:
                hello[field_name] = rng.choice(NON_FINITE)
                return _packed(hello)
            return _text(hello)
        if kind == 8:  # missing parts, wrong v
            return _text(rng.choice([{"values": {}}, {"t": 1.0}, {"t": 1.0, "v": [1.0, 2.0]}, {"t": 1.0, "v": "x"}]))
        if kind == 9:  # not an object, not JSON, not msgpack
            if rng.random() < 0.5:
                return rng.choice(["[]", '"x"', "1", "null", "{", '{"t": }', "\ud7ff" * 3])
            return rng.randbytes(rng.randrange(1, 64))
        if kind == 10:  # oversize: in bytes, not characters
            if rng.random() < 0.0005:
                return HUGE  # beyond the websocket limit: closed with 1009, counted
            return rng.choice(OVERSIZE)
        if kind == 11:  # deep nesting
            return rng.choice(DEEP)
        if kind == 12:
            return _text({"type": rng.choice(["dance", "", None, 1, "frame"]), "t": self._clock(), "values": {}})
        if kind == 13:  # huge integers and odd numbers
            return '{"t": 123456789012345678901234567890, "values": {"lfHoof.ty": 1e999}}'
        return _text({"t": self._clock(), "values": self._plausible(), "future_field": [1, {"a": None}]})

    def rider(self) -> str | bytes:
        rng = self.rng
        kind = rng.randrange(8)
        if kind <= 3:
            field_name = rng.choice(["rate", "decimation", "channels", "horse_channels", "encoding", "bones"])
            bad_fields: dict[str, list[Any]] = {
                "rate": [1e-300, 1e-10, 0.0, -1.0, 1e300, "fast", rng.uniform(0.2, 200.0)],
                "decimation": [0, -1, 10**6, 2**70, 1.5, "x", rng.randint(1, 1000)],
                "channels": [["nope"], ["head.rz", "head.rz"], "head.rz", rng.sample(RIDER_NAMES, 3), []],
                "horse_channels": [["nope"], [1], rng.sample(HORSE_NAMES, 2)],
                "encoding": ["xml", ["json"], None, "json", "binary"],
                "bones": ["yes", 1, True, False],
            }
            value = rng.choice(bad_fields[field_name])
            return _text({"type": "subscribe", field_name: value})
        if kind == 4:
            return _text({"type": "ping", "id": rng.choice([1, "a" * 100, [1], {"x": 1}, None, 2.5])})
        if kind == 5:
            return _packed({"type": "subscribe", "rate": rng.choice(NON_FINITE)})
        if kind == 6:
            return rng.choice(["{", "[]", '{"type": "dance"}', *OVERSIZE])
        return rng.randbytes(rng.randrange(1, 32))

    def rest(self) -> tuple[str, str, bytes]:
        rng = self.rng
        literal = rng.choice(LITERALS)
        name = json.dumps(rng.choice([".", "..", "../app", "/etc/passwd", "a.b", "", "x" * 65, "-x", "nope", "é", 3]))
        return rng.choice(
            [
                ("PATCH", "/api/params", f'{{"head.offset": {literal}}}'.encode()),
                ("PATCH", "/api/params", f'{{"no.such": 1, "smoothing.time_constant": {literal}}}'.encode()),
                ("PUT", "/api/animator", f'{{"offsets": {{"head.rz": {literal}}}}}'.encode()),
                ("PUT", "/api/animator", f'{{"gains": {{"bad.channel": 1.0}}, "x": {literal}}}'.encode()),
                ("PUT", "/api/source", f'{{"kind": "procedural", "speed": {literal}}}'.encode()),
                ("PUT", "/api/source", f'{{"kind": "replay", "take": {name}}}'.encode()),
                ("PUT", "/api/source", b'{"kind": "dance"}'),
                ("PUT", "/api/preset", f'{{"name": {name}}}'.encode()),
                ("POST", "/api/record/start", f'{{"name": {name}, "overwrite": {literal}}}'.encode()),
                ("POST", "/api/horse/perform", f'{{"move": {literal}}}'.encode()),
                ("PATCH", "/api/params", rng.randbytes(rng.randrange(1, 40))),
                ("PUT", "/api/preset", b"{" + b" " * 70000 + b"}"),
            ]
        )

    def message(self, weights: tuple[float, float, float] = (0.6, 0.3, 0.1)) -> Message:
        channel = self.rng.choices(("horse", "rider", "rest"), weights)[0]
        return channel, getattr(self, channel)()


# -- the clean reader and producer --------------------------------------------------------


@dataclass
class Reader:
    """Every frame of /ws/rider, checked as it arrives."""

    low: list[float]
    high: list[float]
    frames: int = 0
    non_finite: int = 0
    out_of_range: int = 0
    frozen_runs: int = 0
    reconnects: int = 0
    """Times the clean reader's connection was lost (the service must never drop it)."""
    first_seq: int = -1
    last_seq: int = -1
    _same_since: float | None = None
    _last_values: list[float] | None = None
    problems: list[str] = field(default_factory=list)

    def take(self, frame: dict[str, Any]) -> None:
        """One frame; frozen is judged on engine time (the tick's), not on arrival."""
        values = frame["values"]
        at = frame["t"]
        self.frames += 1
        self.first_seq = frame["seq"] if self.first_seq < 0 else self.first_seq
        self.last_seq = frame["seq"]
        if not all(isinstance(v, float | int) and math.isfinite(v) for v in values):
            self.non_finite += 1
            self.problems.append(f"non-finite frame {frame['seq']}")
            return
        outside = [
            RIDER_NAMES[i]
            for i, (v, lo, hi) in enumerate(zip(values, self.low, self.high, strict=True))
            if not lo - 1e-9 <= v <= hi + 1e-9
        ]
        if outside:
            self.out_of_range += 1
            self.problems.append(f"frame {frame['seq']}: {outside[0]} out of range")
        if values == self._last_values and frame["driver"] != "neutral":
            self._same_since = at if self._same_since is None else self._same_since
            if at - self._same_since >= FROZEN:
                self.frozen_runs += 1
                self.problems.append(f"frozen from frame {frame['seq']}")
                self._same_since = None
        else:
            self._same_since = None
        self._last_values = values


async def clean_reader(url: str, reader: Reader, stop: asyncio.Event) -> None:
    while not stop.is_set():
        try:
            async with connect(url + "/ws/rider", max_size=2**24) as ws:
                while not stop.is_set():
                    try:
                        message = await asyncio.wait_for(ws.recv(), 1.0)
                    except TimeoutError:
                        continue
                    obj = json.loads(message)
                    if obj.get("type") == "frame":
                        reader.take(obj)
        except (ConnectionClosed, OSError):
            reader.reconnects += 1
            await asyncio.sleep(0.1)


async def clean_producer(url: str, stop: asyncio.Event) -> None:
    t0 = time.perf_counter()
    n = 0
    while not stop.is_set():
        try:
            async with connect(url + "/ws/horse") as ws:
                await ws.recv()
                await ws.send(json.dumps({"type": "hello", "name": "clean", "priority": 1000}))
                while not stop.is_set():
                    n += 1
                    await asyncio.sleep(max(0.0, t0 + n / 120.0 - time.perf_counter()))
                    t = time.perf_counter() - t0
                    values = {"rearPivot.rz": 4.0 * math.sin(5.0 * t), "lfHoof.ty": 0.1 + 0.1 * math.sin(9.0 * t)}
                    await ws.send(msgpack.packb({"t": t, "values": values}))
        except (ConnectionClosed, OSError):
            await asyncio.sleep(0.1)


def clean_side(url: str, low: list[float], high: list[float], stop: Any, out: Any) -> None:
    """The clean producer and reader, in a process of their own (the hostile clients cannot starve them)."""

    async def run() -> Reader:
        reader = Reader(low, high)
        done = asyncio.Event()
        tasks = [asyncio.create_task(clean_reader(url, reader, done)), asyncio.create_task(clean_producer(url, done))]
        while not stop.is_set():
            await asyncio.sleep(0.1)
        done.set()
        await asyncio.gather(*tasks, return_exceptions=True)
        return reader

    out.put(asyncio.run(run()))


# -- hostile connections ------------------------------------------------------------------


@dataclass
class Tally:
    """What the hostile clients sent and saw."""

    sent: int = 0
    ws_errors: Counter[str] = field(default_factory=Counter)
    closes: Counter[int] = field(default_factory=Counter)
    rest: Counter[int] = field(default_factory=Counter)


async def hostile_socket(
    url: str, path: str, make: Callable[[], str | bytes], quota: int, tally: Tally, seed: int
) -> None:
    """Send ``quota`` messages on ``path``, reconnecting when the service closes the connection.

    Before leaving, a barrier (a message the service answers) makes sure every answer
    to the messages before it has arrived, so rejects seen and counted can be compared.
    """
    rng = random.Random(seed)
    left = quota
    while left > 0:
        token = f"barrier-{seed}-{left}"
        barrier = asyncio.Event()
        try:
            async with connect(url + path, max_size=2**25, open_timeout=30) as ws:
                await ws.recv()  # welcome / hello
                reader = asyncio.create_task(_drain(ws, tally, token, barrier))
                try:
                    while left > 0:
                        await ws.send(make())
                        left -= 1
                        tally.sent += 1
                        await asyncio.sleep(0)  # let the reader and keepalive pings run
                        if rng.random() < 0.001:
                            break  # leave, and come back
                    marker = {"type": token} if path == "/ws/horse" else {"type": "ping", "id": token}
                    await ws.send(json.dumps(marker))
                    await asyncio.wait_for(barrier.wait(), 60.0)
                except ConnectionClosed:
                    await asyncio.wait_for(barrier.wait(), 60.0)  # the reader records the close
                finally:
                    reader.cancel()
                    await asyncio.gather(reader, return_exceptions=True)
        except (ConnectionClosed, OSError, TimeoutError):
            await asyncio.sleep(0.1)


async def _drain(ws: Any, tally: Tally, token: str, barrier: asyncio.Event) -> None:
    try:
        async for message in ws:
            if isinstance(message, str):
                if message.startswith('{"type":"error"'):
                    tally.ws_errors[json.loads(message)["reason"]] += 1
                if token in message:
                    barrier.set()
    except ConnectionClosed as closed:
        if closed.rcvd is not None:
            tally.closes[closed.rcvd.code] += 1
    finally:
        barrier.set()


async def hostile_rest(base: str, make: Callable[[], tuple[str, str, bytes]], quota: int, tally: Tally) -> None:
    async with httpx.AsyncClient(base_url=base, timeout=20.0) as client:
        for _ in range(quota):
            method, path, body = make()
            response = await client.request(method, path, content=body, headers={"content-type": "application/json"})
            tally.sent += 1
            if response.status_code >= 500:
                raise AssertionError(f"{method} {path} {body[:80]!r}: {response.status_code} {response.text[:200]}")
            if 400 <= response.status_code < 500:
                tally.rest[response.status_code] += 1


# -- the run ------------------------------------------------------------------------------


def metrics(text: str, name: str) -> dict[str, float]:
    """``{label value: sample}`` of one labelled metric (``{"": v}`` when unlabelled)."""
    out = {}
    for match in re.finditer(rf'^{name}(?:{{\w+="([^"]*)"}})? (\S+)$', text, re.M):
        out[match.group(1) or ""] = float(match.group(2))
    return out


def delta(after: dict[str, float], before: dict[str, float]) -> dict[str, float]:
    return {k: v - before.get(k, 0.0) for k, v in after.items() if v - before.get(k, 0.0)}


async def fuzz(
    base_http: str, base_ws: str, messages: int, connections: int, seed: int, length_scale: float = 25.0
) -> dict[str, Any]:
    """Run the hostile clients against a running service (``tick.length_scale``); return the findings."""
    async with httpx.AsyncClient(base_url=base_http, timeout=20.0) as client:
        before = (await client.get("/metrics")).text
        kept = {path: (await client.get(path)).json() for path in ("/api/params", "/api/animator", "/api/presets")}
    low, high = DEFAULT_RANGES.limits(RIDER_NAMES, length_scale)
    context = multiprocessing.get_context("spawn")
    stop, out = context.Event(), context.Queue()
    clean = context.Process(target=clean_side, args=(base_ws, low, high, stop, out), name="fuzz-clean-side")
    clean.start()
    await asyncio.sleep(2.0)
    tally = Tally()
    rest_quota = max(1, messages // 50)
    per = max(1, (messages - rest_quota) // connections)
    tasks = []
    for i in range(connections):
        generator = Hostile(seed * 1000 + i)
        path, make = ("/ws/horse", generator.horse) if i % 3 != 2 else ("/ws/rider", generator.rider)
        tasks.append(hostile_socket(base_ws, path, make, per, tally, seed * 1000 + i))
    tasks.append(hostile_rest(base_http, Hostile(seed * 1000 + 999).rest, rest_quota, tally))
    started = time.perf_counter()
    await asyncio.gather(*tasks)
    elapsed = time.perf_counter() - started
    await asyncio.sleep(1.5)  # the clean reader sees the rider settle
    stop.set()
    reader: Reader = await asyncio.to_thread(out.get, True, 60.0)
    await asyncio.to_thread(clean.join, 10.0)
    async with httpx.AsyncClient(base_url=base_http, timeout=20.0) as client:
        after = (await client.get("/metrics")).text
        state = (await client.get("/api/state")).json()
        # Put back what valid requests among the hostile ones changed (the tick blends back).
        await client.post("/api/record/stop")
        await client.put("/api/source", json={"kind": "live"})
        await client.put("/api/preset", json={"name": kept["/api/presets"]["current"]})
        await client.patch("/api/params", json=kept["/api/params"])
        await client.put("/api/animator", json=kept["/api/animator"])
    await asyncio.sleep(1.0)
    counted = delta(metrics(after, "riderlive_bad_frames_total"), metrics(before, "riderlive_bad_frames_total"))
    rest = delta(metrics(after, "riderlive_rest_rejected_total"), metrics(before, "riderlive_rest_rejected_total"))
    seen = Counter(tally.ws_errors)
    seen["oversize"] += tally.closes.get(1009, 0)
    skipped = delta(metrics(after, "riderlive_tick_skipped_total"), metrics(before, "riderlive_tick_skipped_total"))
    span = reader.last_seq - reader.first_seq + 1
    return {
        "sent": tally.sent,
        "seconds": elapsed,
        "rejects_seen": dict(seen),
        "rejects_counted": {k: int(v) for k, v in counted.items()},
        "rest_seen": {str(k): v for k, v in tally.rest.items()},
        "rest_counted": {k: int(v) for k, v in rest.items()},
        "closes": dict(tally.closes),
        "tick_alive": state["tick_alive"],
        "internal_errors": int(counted.get("internal_error", 0)),
        "reader": reader,
        "delivery": reader.frames / max(1, span),
        "skipped": int(skipped.get("", 0.0)),
        "state_resets": state["counters"].get("state_resets", 0.0),
        "outputs_clamped": state["counters"].get("outputs_clamped", 0.0),
    }


def verdict(result: dict[str, Any]) -> dict[str, bool]:
    reader: Reader = result["reader"]
    return {
        "service and tick alive": bool(result["tick_alive"]),
        "no internal error": result["internal_errors"] == 0,
        "0 non-finite outputs": reader.non_finite == 0,
        "0 out-of-range outputs": reader.out_of_range == 0,
        "0 frozen outputs": reader.frozen_runs == 0,
        "the clean reader never dropped": reader.reconnects == 0,
        "every websocket reject counted": result["rejects_seen"] == result["rejects_counted"],
        "every REST reject counted": result["rest_seen"] == result["rest_counted"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--messages", type=int, default=1_000_000)
    parser.add_argument("--connections", type=int, default=6)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--no-burner", action="store_true")
    args = parser.parse_args()
    workdir = Path(tempfile.mkdtemp(prefix="fuzz-service-"))
    (workdir / "service.toml").write_text(CONFIG)
    server, port = start_server(workdir / "service.toml")
    try:
        failure = None
        with busy_cores(0 if args.no_burner else 1, 7200):
            try:
                result = asyncio.run(
                    fuzz(
                        f"http://127.0.0.1:{port}", f"ws://127.0.0.1:{port}", args.messages, args.connections, args.seed
                    )
                )
            except Exception as exc:  # the service went away under the hostile clients: say what it said
                failure = exc
        alive = server.poll() is None
    finally:
        server.terminate()
        try:
            _, log = server.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            server.kill()
            _, log = server.communicate()
    if failure is not None:
        print(f"FAILED: {type(failure).__name__}: {failure}; server alive: {alive}, exit code {server.returncode}")
        print("".join(log.splitlines(keepends=True)[-40:]))
        sys.exit(1)
    reader: Reader = result["reader"]
    print(f"{result['sent']} hostile messages in {result['seconds']:.0f} s; other core busy: {not args.no_burner}")
    print(f"  rejects seen by the clients:  {dict(sorted(result['rejects_seen'].items()))}")
    print(f"  rejects counted by /metrics:  {dict(sorted(result['rejects_counted'].items()))}")
    print(f"  REST 4xx seen / counted: {result['rest_seen']} / {result['rest_counted']}; closes: {result['closes']}")
    print(
        f"  clean reader: {reader.frames} frames, {result['delivery']:.4f} of its seq span (the tick skipped "
        f"{result['skipped']} deadlines in the run); "
        f"non-finite {reader.non_finite}, out of range {reader.out_of_range}, frozen {reader.frozen_runs}"
    )
    print(f"  tick: state resets {result['state_resets']:.0f}, values clamped {result['outputs_clamped']:.0f}")
    for problem in reader.problems[:5]:
        print(f"  problem: {problem}")
    checks = verdict(result) | {"server alive until stopped": alive, "no traceback in its log": "Traceback" not in log}
    for check, ok in checks.items():
        print(f"  {check}: {'met' if ok else 'NOT met'}")


if __name__ == "__main__":
    main()
