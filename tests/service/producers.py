"""Test producers and a subscriber that follows /ws/rider in a thread."""

from __future__ import annotations

import contextlib
import json
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import msgpack
from websockets.sync.client import ClientConnection, connect

from riderlive.channels import HORSE_NAMES
from tests.waiting import Inbox


class Producer:
    """Streams frames ``make(t) -> dict`` at ``rate`` Hz to /ws/horse (or ``path``) in a thread."""

    def __init__(
        self,
        url: str,
        make: Callable[[float], dict[str, Any]],
        rate: float = 100.0,
        hello: dict[str, Any] | None = None,
        binary: bool = False,
        path: str = "/ws/horse",
        **connect_kwargs: Any,
    ) -> None:
        self.ws: ClientConnection = connect(url + path, **connect_kwargs).__enter__()
        self.welcome = json.loads(self.ws.recv(timeout=5))
        self.make, self.rate, self.binary = make, rate, binary
        self.inbox: Inbox[dict[str, Any]] = Inbox()
        self.messages = self.inbox.items
        self.sending = threading.Event()
        self.sending.set()
        self.closed = threading.Event()
        if hello:
            self.ws.send(json.dumps({"type": "hello", **hello}))
        threading.Thread(target=self._send, daemon=True).start()
        threading.Thread(target=self._recv, daemon=True).start()

    def _send(self) -> None:
        t0 = time.perf_counter()
        n = 0
        while not self.closed.is_set():
            n += 1
            time.sleep(max(0.0, t0 + n / self.rate - time.perf_counter()))
            if not self.sending.is_set():
                continue
            frame = self.make(time.perf_counter() - t0)
            try:
                self.ws.send(msgpack.packb(frame) if self.binary else json.dumps(frame))
            except Exception:
                return

    def _recv(self) -> None:
        try:
            for message in self.ws:
                self.inbox.append(json.loads(message))
        except Exception:
            pass

    def driving(self) -> bool | None:
        controls = [m["driving"] for m in self.messages if m.get("type") == "control"]
        return controls[-1] if controls else None

    def wait_control(self, timeout: float = 5.0) -> bool:
        """Whether it drives, once the service has said (its answer to the first frame, or a change)."""
        self.inbox.wait_for(lambda m: m.get("type") == "control", timeout)
        return bool(self.driving())

    def wait_driving(self, expected: bool, timeout: float = 5.0) -> bool:
        """Whether the service's last word is ``expected``, waiting up to ``timeout`` s for it: the
        control message travels on this socket, the frames it changed on another, in any order."""
        with contextlib.suppress(AssertionError):
            self.inbox.wait_for(lambda m: m.get("type") == "control" and self.driving() is expected, timeout)
        return self.driving() is expected

    def close(self) -> None:
        self.closed.set()
        self.ws.close()


class Stream:
    """Streams recorded rows (``times`` s, ``rows``) to ``path`` at their own timing, in a thread."""

    def __init__(self, url: str, path: str, times: Any, rows: Any, hello: dict[str, Any] | None = None) -> None:
        self.ws: ClientConnection = connect(url + path).__enter__()
        self.welcome = json.loads(self.ws.recv(timeout=5))
        if hello:
            self.ws.send(json.dumps({"type": "hello", **hello}))
        self.times, self.rows = [float(t) for t in times], [list(map(float, r)) for r in rows]
        self.messages: list[dict[str, Any]] = []
        self.started = time.perf_counter()
        self.done = threading.Event()
        threading.Thread(target=self._send, daemon=True).start()
        threading.Thread(target=self._recv, daemon=True).start()

    def _send(self) -> None:
        t0 = self.times[0]
        try:
            for t, row in zip(self.times, self.rows, strict=True):
                time.sleep(max(0.0, self.started + (t - t0) - time.perf_counter()))
                self.ws.send(json.dumps({"t": t, "v": row}))
        except Exception:
            pass
        self.done.set()

    def _recv(self) -> None:
        try:
            for message in self.ws:
                self.messages.append(json.loads(message))
        except Exception:
            pass

    def close(self) -> None:
        self.ws.close()


def constant(values: dict[str, float]) -> Callable[[float], dict[str, Any]]:
    return lambda t: {"t": t, "values": values}


class Follower:
    """Every frame of /ws/rider in a thread, each a dict as sent (``t``: the service's engine
    time s, ``values``: the rider's channels) with ``at``, its arrival, and ``ticked``, its
    tick (``t`` plus the hello's ``engine_epoch``), both this process's perf_counter s (one
    host: the service's and this process's clocks are both CLOCK_MONOTONIC); tests wait on
    its arrivals. ``horse_channels``: the horse channels asked
    for beside the rider's (every one by default; only frames carrying them are kept), None for
    the rider's alone (every frame kept). ``connect_kwargs`` go to websockets' ``connect``."""

    def __init__(self, url: str, horse_channels: Sequence[str] | None = HORSE_NAMES, **connect_kwargs: Any) -> None:
        self.ws = connect(url + "/ws/rider", **connect_kwargs).__enter__()
        self.hello = json.loads(self.ws.recv(timeout=10))
        self.epoch: float = self.hello["engine_epoch"]
        subscribe: dict[str, Any] = {"type": "subscribe"}
        if horse_channels is not None:
            subscribe["horse_channels"] = list(horse_channels)
        self.ws.send(json.dumps(subscribe))
        self._horse = horse_channels is not None
        self.inbox: Inbox[dict[str, Any]] = Inbox()
        self.frames = self.inbox.items
        threading.Thread(target=self._recv, daemon=True).start()

    def _recv(self) -> None:
        try:
            for message in self.ws:
                at = time.perf_counter()
                obj = json.loads(message)
                if obj.get("type") == "frame" and ("horse" in obj or not self._horse):
                    obj["at"] = at
                    obj["ticked"] = obj["t"] + self.epoch
                    self.inbox.append(obj)
        except Exception:
            pass

    def first_ticked_after(self, at: float, start: int = 0) -> int | None:
        """Index of the first frame (from ``start``) ticked after ``at`` (perf_counter s). A frame
        the stopped or killed tick wrote before ``at`` but that arrives after is not one. None if
        none yet."""
        for i, frame in enumerate(list(self.frames[start:]), start):
            if frame["ticked"] > at:
                return i
        return None

    def wait_for(
        self, predicate: Callable[[dict[str, Any]], bool], timeout: float = 5.0, start: int | None = None
    ) -> dict[str, Any]:
        """The first frame from now on (or from index ``start``: a mark taken before what made
        the frame, which may have come and gone by now) that matches (woken by each arrival)."""
        return self.inbox.wait_for(predicate, timeout, start=len(self.frames) if start is None else start)

    def after(
        self,
        frame: dict[str, Any],
        count: int,
        where: Callable[[dict[str, Any]], bool] = lambda f: True,
        timeout: float = 10.0,
    ) -> list[dict[str, Any]]:
        """``frame`` and the frames after it, once ``count`` of them match ``where`` (ticks, not seconds)."""
        seq = frame["seq"]
        self.inbox.wait_count(lambda f: f["seq"] > seq and where(f), count, timeout)
        return self.since(frame)

    def since(self, frame: dict[str, Any]) -> list[dict[str, Any]]:
        return [f for f in self.frames if f["seq"] >= frame["seq"]]

    def close(self) -> None:
        self.ws.close()
