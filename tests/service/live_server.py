"""Run the real ``riderlive serve`` in a subprocess on a free loopback port."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import httpx

from tests.children import popen
from tests.waiting import wait_until

ROOT = Path(__file__).resolve().parents[2]
HTTP = httpx.Client()
"""One client for every server's requests in this run: ``httpx.get`` builds a client, and
with it an SSL context from the CA bundle, per call: 81 ms of CPU a call at load 20 against
3 ms for a kept client (2 ms quiet-ish for urllib), and the start-up poll of
:meth:`LiveServer.wait_for_ticks` made ~12 of them a second for the 10-60 s a server takes
to start on the shared host. Thread-safe; a connection to a stopped server fails (connect
error) as a new one did."""


class LiveServer:
    """``riderlive serve --config FILE --port 0``; its stderr is kept in ``log``."""

    def __init__(
        self,
        config_text: str,
        workdir: Path,
        host: str = "127.0.0.1",
        port: int = 0,
        token: str | None = None,
        wait_for_ticks: bool = True,
        start_timeout_s: float = 120.0,
    ) -> None:
        """``wait_for_ticks`` False: return once the web process is up (call :meth:`wait_for_ticks`).
        ``start_timeout_s``: for the web process to listen, then for the first ticks (each).
        No test here times the start, so the bound is wide: on the 2 shared cores at load ~20
        the imports alone took 30-60 s, and a 30 s bound failed a session fixture and with it
        every test of its module (146 errors in one run); a quick start returns at once."""
        self.token = token
        self.workdir = workdir
        self.host = host
        config = workdir / "service.toml"
        config.write_text(config_text)
        env = dict(os.environ, PYTHONPATH=str(ROOT), PYTHONUNBUFFERED="1")
        command = [
            sys.executable,
            "-m",
            "riderlive",
            "serve",
            "--config",
            str(config),
            "--host",
            host,
            "--port",
            str(port),
        ]
        self.proc = popen(
            command,  # SIGTERM (a clean stop) if the test run dies (tests/children.py)
            cwd=workdir,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.log: list[str] = []
        self._ready = threading.Event()
        self.port = 0
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        if not self._ready.wait(start_timeout_s):
            self.stop()
            raise RuntimeError("server did not start:\n" + "".join(self.log))
        self.base = f"http://{host}:{self.port}"
        self.ws = f"ws://{host}:{self.port}"
        if wait_for_ticks:
            self.wait_for_ticks(start_timeout_s)

    def wait_for_ticks(self, timeout: float = 120.0) -> None:
        """The tick process is spawned at startup and needs a moment to import (``timeout``:
        wide, as ``start_timeout_s``; 30 s failed test_tail_live's fixture at load 16, the
        tail's kernels loading): until /readyz
        says it beats (every 0.1 s), then until it has ticked 10 times (/api/state, 0.05 s).
        /readyz costs the web process ~40 % less CPU than /api/state (3.5-4.5 against
        5.5-7 ms a request at load 18), and a start takes 3-60 s, most of it importing:
        at 20 /api/state polls a second that was ~0.18 s of CPU per second of start, now
        ~0.06 (docs/performance.md, branch livefast)."""

        def beating() -> bool:
            try:
                return self.get("/readyz").status_code == 200
            except httpx.HTTPError:
                return False

        def ticking() -> bool:
            try:
                return bool(self.get("/api/state", headers=self.auth).json()["counters"].get("ticks", 0) > 10)
            except (httpx.HTTPError, ValueError, KeyError):
                return False

        try:
            wait_until(beating, timeout, poll=0.1)
            wait_until(ticking, timeout, poll=0.05)
        except AssertionError:
            self.stop()
            raise RuntimeError("the tick never started:\n" + "".join(self.log)) from None

    def devices(self) -> dict[str, Any]:
        """``GET /api/devices`` (with this server's token): each device's state, supervision."""
        result: dict[str, Any] = self.get("/api/devices", headers=self.auth).json()
        return result

    def wait_guardian(self, timeout: float = 60.0) -> None:
        """Until the devices' guardian reports alive: an arm before that is refused (503,
        ``no_guardian``), as it should be. The guardian starts beside the tick and on a
        loaded host reports alive seconds after the first ticks."""

        def alive() -> bool:
            try:
                return bool(self.get("/api/devices", headers=self.auth).json()["supervision"]["guardian"]["alive"])
            except (httpx.HTTPError, ValueError, KeyError, TypeError):
                return False

        wait_until(alive, timeout, lambda: "".join(self.log[-30:]), poll=0.05)

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.log.append(line)
            match = re.search(r"listening on port (\d+)", line)
            if match:
                self.port = int(match.group(1))
            if "Application startup complete" in line:
                self._ready.set()

    @property
    def auth(self) -> dict[str, str]:
        """The Authorization header for this server's token ({} without one)."""
        return {"Authorization": f"Bearer {self.token}"} if self.token else {}

    def get(self, path: str, timeout: float = 10.0, **kwargs: object) -> httpx.Response:
        return HTTP.get(self.base + path, timeout=timeout, **kwargs)  # type: ignore[arg-type]

    def request(self, method: str, path: str, **kwargs: object) -> httpx.Response:
        return HTTP.request(method, self.base + path, timeout=10.0, **kwargs)  # type: ignore[arg-type]

    def metric(self, name: str, labels: str = "") -> float:
        """One sample of /metrics (0 when absent)."""
        wanted = f"{name}{{{labels}}}" if labels else name
        for line in self.get("/metrics").text.splitlines():
            if line.startswith(wanted + " "):
                return float(line.rsplit(" ", 1)[1])
        return 0.0

    def stop(self, sig: int = signal.SIGINT, timeout: float = 15.0) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5.0)
        self._reader.join(5.0)  # its last lines in ``log`` (the reader ends at the pipe's end)
        return self.proc.returncode
