"""The real service (uvicorn, its own process, a free loopback port) and a real headless Chromium."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

import riderlive
from riderlive.web import CHROMIUM, CHROMIUM_ARGS
from tests.children import popen
from tests.waiting import wait_until

PACKAGE_ROOT = Path(riderlive.__file__).resolve().parents[1]
"""Where the tests import riderlive from: the server runs that same code."""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class Server:
    """A running ``riderlive serve`` on 127.0.0.1."""

    port: int
    workdir: Path
    extra_config: str = ""
    """More TOML sections for the service's config."""
    process: subprocess.Popen[bytes] | None = None
    log: list[Path] = field(default_factory=list)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self, timeout: float = 20.0) -> None:
        config = self.workdir / "service.toml"
        config.write_text(
            f'[server]\nport = {self.port}\n\n[takes]\ndirectory = "{self.workdir / "takes"}"\n\n{self.extra_config}'
        )
        log = self.workdir / f"serve-{len(self.log)}.log"
        self.log.append(log)
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(PACKAGE_ROOT), os.environ.get("PYTHONPATH", "")])}
        with log.open("wb") as out:
            self.process = popen(
                [sys.executable, "-m", "riderlive", "serve", "--config", str(config)],
                cwd=self.workdir,
                stdout=out,
                stderr=subprocess.STDOUT,
                env=env,
                start_new_session=True,  # its own process group: stop() ends the tick process too
            )

        def answers() -> bool:
            if self.process is None or self.process.poll() is not None:
                return True
            with contextlib.suppress(OSError):
                self.get("/api/state")
                return True
            return False

        try:
            wait_until(answers, timeout, poll=0.05)
        except AssertionError:
            self.stop()  # never leave a server that did not answer behind
            raise RuntimeError(f"server did not answer within {timeout} s: {log.read_text()[-2000:]}") from None
        if self.process is None or self.process.poll() is not None:
            self.stop()
            raise RuntimeError(f"server exited: {log.read_text()[-2000:]}")

    def stop(self) -> None:
        """SIGTERM (the service parks and exits), then kill whatever is left of its process group."""
        process, self.process = self.process, None
        if process is None:
            return
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
            try:
                process.wait(10)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait(5)
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(process.pid, signal.SIGKILL)  # a child the service left (it should leave none)

    def request(self, method: str, path: str, body: Any = None) -> Any:
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.url + path, data=data, method=method)
        if data is not None:
            req.add_header("content-type", "application/json")
        with urllib.request.urlopen(req, timeout=5) as res:
            return json.loads(res.read() or b"null")

    def get(self, path: str) -> Any:
        return self.request("GET", path)


def _needs_service() -> None:
    pytest.importorskip("riderlive.service", reason="the live service (issue 4) is not on this branch yet")
    if not Path(CHROMIUM).exists():
        pytest.fail(f"{CHROMIUM} is missing: apt-get install chromium (.ci/run does it)")


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    _needs_service()
    s = Server(free_port(), tmp_path_factory.mktemp("serve"))
    try:
        s.start()
        yield s
    finally:
        s.stop()


@pytest.fixture(scope="session")
def browser() -> Iterator[Any]:
    _needs_service()
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=list(CHROMIUM_ARGS))
        yield b
        b.close()


@dataclass
class PageUnderTest:
    page: Any
    errors: list[str]

    def state(self, expr: str) -> Any:
        return self.page.evaluate(f"() => {expr}")

    def wait_for(self, expr: str, timeout: float = 10.0) -> Any:
        self.page.wait_for_function(f"() => {expr}", timeout=timeout * 1000)
        return self.state(expr)


def open_page(browser: Any, url: str, path: str = "/") -> PageUnderTest:
    page = browser.new_page(viewport={"width": 1280, "height": 760})
    errors: list[str] = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(f"uncaught: {e}"))
    page.goto(url + path)
    return PageUnderTest(page, errors)


@pytest.fixture(scope="module")
def live_page(browser: Any, server: Server) -> Iterator[PageUnderTest]:
    """One page for the module's tests (each leaves the service as it found it)."""
    p = open_page(browser, server.url)
    p.wait_for("window.riderlive && riderlive.connected && riderlive.frames > 5", timeout=40)
    yield p
    p.page.close()
