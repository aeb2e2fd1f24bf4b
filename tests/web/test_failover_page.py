"""The page during a failover, in a real headless Chromium: the real service with a rig on
the emulated bus (its own process) and the guardian.

With the rig armed and running, ``kill -9`` and then SIGSTOP of the tick: the page says
the tick is down and shows the rig as the guardian reports it (``parking``, ``parked``,
``outputs off`` or ``unknown``), never the dead generation's ``running``; then the next
generation is up and the page shows the rig ``disarmed`` (never re-armed). What the page
showed is recorded in the page itself (a MutationObserver on the header's driver and rig
lines), so no state between two polls is missed.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.dynamixel.rig_harness import servo_emulator
from tests.service.test_rig_hookup import relaxed_rig
from tests.waiting import wait_until
from tests.web.conftest import STATE_FPS, PageUnderTest, Server, open_page

pytestmark = pytest.mark.browser
TOKEN = "page-failover-1"
ROOT = Path(__file__).resolve().parents[2]
DOWN_STATES = ("parking", "parked", "outputs off", "unknown", "disconnected")
"""What a device may show while its tick is down (``realtime/down.py``: the guardian's report)."""
RECORD = """() => {
  const seen = (window.__seen = []);
  const note = () => seen.push([document.getElementById('driver').textContent,
                                document.getElementById('rigstate').textContent]);
  const watch = new MutationObserver(note);
  for (const id of ['driver', 'rigstate'])
    watch.observe(document.getElementById(id), {childList: true, characterData: true, subtree: true});
  note();
}"""


@pytest.fixture(scope="module")
def rig_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    workdir = tmp_path_factory.mktemp("failover-page")
    rig_file = relaxed_rig(workdir)
    with servo_emulator(rig_file) as port:
        extra = (
            f'[tick]\nrate = 100.0\nrealtime_priority = false\n[security]\ntoken = "{TOKEN}"\n'
            f'[rig]\nfile = "{rig_file}"\nport = "{port}"\n'
        )
        server = Server(0, workdir, extra_config=extra)
        server.start()
        try:
            yield server
        finally:
            server.stop()


def call(server: Server, method: str, path: str, body: Any = None) -> Any:
    data = None if body is None else json.dumps(body).encode()
    request = urllib.request.Request(server.url + path, data=data, method=method)
    request.add_header("authorization", f"Bearer {TOKEN}")
    if data is not None:
        request.add_header("content-type", "application/json")
    with urllib.request.urlopen(request, timeout=5) as response:
        return json.loads(response.read() or b"null")


def devices(server: Server) -> dict[str, Any]:
    result: dict[str, Any] = call(server, "GET", "/api/devices")
    return result


def rig_state(server: Server) -> str:
    found = devices(server)["devices"]
    return str(found[0]["state"]) if found else "none"


@pytest.fixture(scope="module")
def page(browser: Any, rig_server: Server) -> Iterator[PageUnderTest]:
    p = open_page(browser, rig_server.url, f"/#token={TOKEN}", max_fps=STATE_FPS)
    p.wait_for("window.riderlive && riderlive.connected && riderlive.frames > 5", timeout=60)
    yield p
    p.page.close()


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGSTOP], ids=["kill-9", "sigstop"])
def test_the_page_shows_the_tick_down_and_the_guardians_report_never_running(
    page: PageUnderTest, rig_server: Server, sig: signal.Signals
) -> None:
    server = rig_server
    wait_until(lambda: rig_state(server) == "disarmed", 60, lambda: devices(server), poll=0.1)
    wait_until(lambda: devices(server)["supervision"]["guardian"]["alive"], 30, lambda: devices(server), poll=0.1)
    call(server, "POST", "/api/arm", {"device": "bench3", "by": "test"})
    wait_until(lambda: rig_state(server) == "running", 30, lambda: devices(server), poll=0.05)
    page.wait_for("document.getElementById('rigstate').textContent.includes(': running')", timeout=15)
    before = devices(server)["supervision"]
    page.page.evaluate(RECORD)
    os.kill(before["tick_pid"], sig)
    try:
        page.wait_for("document.getElementById('driver').textContent.startsWith('tick down')", timeout=15)
        shown_down = page.state("document.getElementById('rigstate').textContent")
        wait_until(
            lambda: (
                devices(server)["supervision"]["generation"] > before["generation"]
                and devices(server)["supervision"]["up"]
            ),
            60,
            lambda: devices(server)["supervision"],
            poll=0.1,
        )
        page.wait_for("!document.getElementById('driver').textContent.startsWith('tick down')", timeout=30)
        page.wait_for("document.getElementById('rigstate').textContent.includes(': disarmed')", timeout=30)
    finally:
        if sig is signal.SIGSTOP:
            with contextlib.suppress(ProcessLookupError):
                os.kill(before["tick_pid"], signal.SIGCONT)
    seen: list[list[str]] = page.state("window.__seen")
    first_down = next(i for i, (driver, _) in enumerate(seen) if driver.startswith("tick down"))
    after = seen[first_down:]
    assert all(": running" not in rig for _, rig in after), after  # never the dead generation's state
    down = [rig for driver, rig in after if driver.startswith("tick down")]
    assert down and all(any(f": {s}" in rig for s in DOWN_STATES) for rig in down), (shown_down, down)
    assert any(": parked" in rig or ": parking" in rig for rig in down), down  # the guardian's report, shown
    assert "disarmed" in after[-1][1] and not after[-1][0].startswith("tick down"), after[-1]
    assert rig_state(server) == "disarmed"  # never re-armed
    assert page.errors == []
