"""The real service (uvicorn, its own process, a free loopback port) and a real headless Chromium.

One service with the default config serves every module of a worker (``shared_server``,
session scope): a start costs ~7 s of CPU and 3-40 s of wall (quiet to loaded), and the
modules leave it as they found it (``server``'s teardown checks the e-stop and the source).
A test that needs another config or restarts its service starts its own :class:`Server`.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
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


@dataclass
class Server:
    """A running ``riderlive serve`` on 127.0.0.1."""

    port: int
    """0: the service picks a free one (read from its log); a restart keeps the port it got."""
    workdir: Path
    extra_config: str = ""
    """More TOML sections for the service's config."""
    process: subprocess.Popen[bytes] | None = None
    log: list[Path] = field(default_factory=list)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self, timeout: float = 120.0) -> None:
        """Until it answers ``GET /api/state``. No test times the start, so the bound is wide:
        at load 19 a start's imports alone took over 20 s (a failed run); a quick start returns at once."""
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
            if self.port == 0:
                said = re.search(r"listening on port (\d+)", log.read_text(errors="replace"))
                if said is None:
                    return False
                self.port = int(said.group(1))
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


@pytest.fixture(scope="package")
def shared_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    """The default service for tests/web, once per worker, stopped when the package ends (an
    idle server costs ~0.55 of a core); fitted presets go to ``presets`` (``tick.preset_dirs``)."""
    _needs_service()
    workdir = tmp_path_factory.mktemp("serve")
    s = Server(0, workdir, extra_config=f'[tick]\npreset_dirs = ["{workdir / "presets"}"]\n')
    try:
        s.start()
        yield s
    finally:
        s.stop()


@pytest.fixture(scope="module")
def server(shared_server: Server) -> Iterator[Server]:
    """The shared service for one module, which must leave it as it found it: live source,
    e-stop clear (checked here, so a module that did not fails itself, not the next one)."""
    yield shared_server
    state = shared_server.get("/api/state")
    assert state["source"] == {"kind": "live"}, f"the module left the source at {state['source']}"
    assert not state["tick"].get("estop"), "the module left the e-stop latched"


@pytest.fixture(scope="package")
def browser() -> Iterator[Any]:
    """Chromium for tests/web, closed when the package ends: Playwright's sync API keeps an
    event loop running on the main thread while it is open, so a later test's ``asyncio.run``
    (tests/bus, tests/service) would fail, as 18 did under ``-n 2 --dist loadfile``."""
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


STATE_FPS = 10.0
"""Draws a second of a page whose tests read its state, not its pixels (``?maxfps``): an open
page otherwise draws every frame in software WebGL, ~0.7 of a core on the loaded host (as
many frames as it gets a CPU for), for as long as it stays open."""


def with_max_fps(path: str, max_fps: float | None) -> str:
    """``path`` (``/``, ``/?render=sticks``, ``/#token=...``) asking the page for ``?maxfps``."""
    if max_fps is None:
        return path
    where, hash_, fragment = path.partition("#")
    return f"{where}{'&' if '?' in where else '?'}maxfps={max_fps:g}{hash_}{fragment}"


def open_page(browser: Any, url: str, path: str = "/", max_fps: float | None = None) -> PageUnderTest:
    """A new page at ``url + path``; ``max_fps``: draw at most that often (the page's ``?maxfps``)."""
    page = browser.new_page(viewport={"width": 1280, "height": 760})
    errors: list[str] = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(f"uncaught: {e}"))
    page.goto(url + with_max_fps(path, max_fps), timeout=120_000)  # a just started service on a busy host
    return PageUnderTest(page, errors)


@pytest.fixture(scope="module")
def live_page(browser: Any, server: Server) -> Iterator[PageUnderTest]:
    """One page for the module's tests (each leaves the service as it found it), drawing at
    most :data:`STATE_FPS` times a second: a module about pixels overrides this fixture."""
    p = open_page(browser, server.url, max_fps=STATE_FPS)
    p.wait_for("window.riderlive && riderlive.connected && riderlive.frames > 5", timeout=40)
    yield p
    p.page.close()
