"""The page never misleads: the header against the real service, in a real headless Chromium.

What the horse does is read from the tick (its status: gait, move) and from the horse
frames (the speed, measured), never from the request; a control that fails says so in
the header and the e-stop banner stays what the service says; the plots' time axis is in
sight at 1440x900 with the four default lanes; streamed input a chosen source leaves unused
is named, with the hand-back.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import re
import signal
import threading
import time
from typing import Any

import pytest

from riderlive.horse import GAIT_TABLE, Gait
from tests.waiting import Pacer, wait_until
from tests.web.conftest import PageUnderTest, Server, open_page

pytestmark = pytest.mark.browser
SPEED = re.compile(r"^horse: (?:(\w+) · )?(\d+\.\d) m/s$")


@pytest.fixture(scope="module")
def page(live_page: PageUnderTest) -> PageUnderTest:
    return live_page


def _header(p: PageUnderTest) -> str:
    return str(p.page.locator("#horse-now").inner_text())


def test_a_source_without_speed_reads_the_speed_the_horse_runs_at(page: PageUnderTest, server: Server) -> None:
    """`PUT /api/source {"kind": "procedural", "gait": "canter"}`: no speed asked, the horse canters at
    its gait's default; the header says the measured speed (it said 0.0 m/s from the request)."""
    canter = GAIT_TABLE[Gait.CANTER].default_speed
    server.request("PUT", "/api/source", {"kind": "procedural", "gait": "canter"})
    try:
        near = f"Math.abs(parseFloat(riderlive.horseText.split(' · ')[1]) - {canter}) < 0.35"
        cantering = "riderlive.horseText && riderlive.horseText.startsWith('horse: canter · ')"
        page.wait_for(f"{cantering} && {near}", timeout=10)
        match = SPEED.match(_header(page))
        assert match is not None, _header(page)
        assert match.group(1) == "canter"
        assert float(match.group(2)) == pytest.approx(canter, abs=0.35)
        assert page.page.locator("#driver").inner_text() == "procedural horse (chosen)"
    finally:
        server.request("PUT", "/api/source", {"kind": "live"})
    assert page.errors == []


def test_after_the_stop_move_the_header_says_the_horse_stands(page: PageUnderTest, server: Server) -> None:
    """The stop move: the header shows the move, then 'standing' at 0.0 m/s while the request
    (and the tick's gait) still say canter."""
    server.request("PUT", "/api/source", {"kind": "procedural", "gait": "canter", "speed": 4.5})
    try:
        page.wait_for("riderlive.horseText && riderlive.horseText.startsWith('horse: canter · ')", timeout=10)
        server.request("POST", "/api/horse/perform", {"move": "stop"})
        page.wait_for("riderlive.horseText.startsWith('horse: stop · ')", timeout=5)
        page.wait_for("riderlive.horseText === 'horse: standing · 0.0 m/s'", timeout=15)
        assert server.get("/api/state")["source"]["gait"] == "canter"  # what was asked, not what it does
        assert page.page.locator("#horse-now").get_attribute("class") == "status warn"
    finally:
        server.request("PUT", "/api/source", {"kind": "live"})
    assert page.errors == []


def test_the_time_axis_is_in_sight_at_1440x900_with_four_lanes(browser: Any, server: Server) -> None:
    p = open_page(browser, server.url)
    try:
        p.page.set_viewport_size({"width": 1440, "height": 900})
        p.wait_for("riderlive.connected && riderlive.plots.chosen.length === 4 && riderlive.plots.axisLabels")
        box = p.page.locator("#plot-axis").bounding_box()
        assert box is not None and box["height"] >= 16
        assert box["y"] >= 0 and box["y"] + box["height"] <= 900, box
        assert p.state("riderlive.plots.axisLabels")[0] == "now"
        inked = p.state(
            "(() => { const c = document.getElementById('plot-axis');"
            " const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;"
            " let n = 0; for (let i = 3; i < d.length; i += 4) if (d[i]) n++; return n; })()"
        )
        assert inked > 50  # the labels are drawn there
        # The lanes still scroll when they do not fit; the axis does not scroll with them.
        p.page.locator("#plot-box").evaluate("b => b.scrollTop = b.scrollHeight")
        assert p.page.locator("#plot-axis").bounding_box() == box
    finally:
        p.page.close()
    assert p.errors == []


def test_streamed_input_left_unused_by_a_chosen_source_is_named_with_the_hand_back(
    page: PageUnderTest, server: Server
) -> None:
    """A producer streams while the procedural source is chosen: the driver line names it as ignored
    and says how to hand back; after `PUT /api/source {"kind": "live"}` it drives."""
    from riderlive.channels import HORSE_NAMES
    from riderlive.client import HorseProducer

    stop = threading.Event()

    async def stream() -> None:
        async with HorseProducer(f"ws://127.0.0.1:{server.port}", name="mocap") as producer:
            # Stamped from the clock, as an engine does: counting 1/60 per send ran ~5 % slow
            # (sleep and send overhead), and a producer clock that slow falls out of the tick's
            # read window within about a second (it drove, then fell back: not a hand-back fault).
            start, pacer = time.monotonic(), Pacer(1 / 60)
            while not stop.is_set():
                await producer.send(time.monotonic() - start, dict.fromkeys(HORSE_NAMES, 0.0))
                await pacer.await_next()

    thread = threading.Thread(target=lambda: asyncio.run(stream()), daemon=True)
    server.request("PUT", "/api/source", {"kind": "procedural", "gait": "trot"})
    thread.start()
    try:
        page.wait_for("riderlive.driverText.includes('live input from mocap ignored')", timeout=10)
        hand_back = 'procedural horse (chosen) · live input from mocap ignored: Source "live" hands back'
        assert page.state("riderlive.driverText") == hand_back
        server.request("PUT", "/api/source", {"kind": "live"})
        page.wait_for("riderlive.driverText === 'live input from mocap'", timeout=10)
    finally:
        stop.set()
        thread.join(5)
        server.request("PUT", "/api/source", {"kind": "live"})
    assert page.errors == []


def test_a_failed_reset_is_shown_and_the_latch_stays_truthful(page: PageUnderTest, server: Server) -> None:
    """E-stop, then Reset while the tick is hung and so is its warm spare (SIGSTOP both: the
    supervisor kills the tick and promotes a spare that cannot answer): the service answers
    503; the header says so and the e-stop banner stays, as the service says. Reset again once
    the tick is back: the alert and the banner go.

    The spare is held too because a warm takeover (``TickLink.promote``) serves ~20 ms after
    the hang is found (``hang_threshold``, 1 s here): a Reset that reaches the service after
    that, e.g. on a loaded host, is answered by the new generation and succeeds, rightly."""
    p = page.page
    server.request("POST", "/api/estop")
    page.wait_for("!document.getElementById('estop-state').hidden", timeout=5)
    spare = lambda: server.get("/api/state")["supervision"]["spare"]  # noqa: E731
    wait_until(lambda: spare()["state"] == "warm", 60, lambda: f"no warm spare: {spare()}", poll=0.1)
    held = [int(server.get("/healthz")["tick_pid"]), int(spare()["pid"])]  # this test's own service's
    for pid in held:
        os.kill(pid, signal.SIGSTOP)
    try:
        p.locator("#reset").click()
        page.wait_for("!document.getElementById('alert').hidden", timeout=10)
        alert = p.locator("#alert").inner_text()
        assert alert.startswith("reset failed: POST /api/reset: 503"), alert
        assert "tick" in alert  # the service's reason: the tick is restarting / did not answer
        assert p.locator("#estop-state").is_visible()
        assert p.locator("#estop-state").inner_text().startswith("E-STOP LATCHED")
        assert server.get("/api/devices")["estop"] is True  # what the banner says is true
    finally:
        for pid in held:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGCONT)

    def ready() -> bool:  # the supervisor's restart: polled, as an operator would
        with contextlib.suppress(OSError):
            return bool(server.get("/readyz").get("status") == "ready")
        return False

    with contextlib.suppress(AssertionError):  # not ready within 30 s: the page must say so below
        wait_until(ready, 30.0, poll=0.2)
    p.locator("#reset").click()
    page.wait_for("document.getElementById('alert').hidden", timeout=30)  # a restarted tick on a busy host
    page.wait_for("document.getElementById('estop-state').hidden", timeout=30)
    assert server.get("/api/devices")["estop"] is False
    # Chromium logs the refused request itself; that line, and only it, is expected here.
    assert [e for e in page.errors if "503" not in e] == []
    page.errors.clear()
