"""The page's saddle panel in a real headless Chromium: the saddle pose of any horse, and a
saddle stream's estimate (gait, stride frequency, lock)."""

from __future__ import annotations

import json
import threading
import time

import numpy as np
import pytest
from websockets.sync.client import connect

from riderlive.channels import HORSE_NAMES
from riderlive.horse import GAIT_TABLE, Gait
from riderlive.horse.script import gait_script
from riderlive.saddle import saddle_from_horse
from riderlive.saddle.synthetic import record
from tests.web.conftest import PageUnderTest, Server

pytestmark = pytest.mark.browser


def test_the_panel_shows_the_saddle_of_the_procedural_horse(live_page: PageUnderTest) -> None:
    live_page.wait_for("riderlive.saddle && riderlive.saddle.pose !== null")
    pose, values, estimate = live_page.state(
        "[riderlive.saddle.pose, riderlive.saddle.values, riderlive.saddle.estimate]"
    )
    np.testing.assert_allclose(pose, saddle_from_horse([values[n] for n in HORSE_NAMES]), atol=1e-9)
    assert estimate is None
    cells = live_page.page.locator("#saddle-pose [data-axis]").all_inner_texts()
    assert len(cells) == 6 and all(c != "–" for c in cells)
    assert "not a saddle" in live_page.page.locator("#saddle-estimate").inner_text()
    assert live_page.errors == []


def test_the_panel_shows_a_saddle_streams_gait_frequency_and_lock(live_page: PageUnderTest, server: Server) -> None:
    recording = record(gait_script("trot", 3.5, seed=2), 100.0, seed=2)
    times, rows = recording.saddle.t, recording.saddle.values
    assert times is not None
    done = threading.Event()

    def stream() -> None:
        with connect(server.url.replace("http", "ws") + "/ws/saddle") as ws:
            json.loads(ws.recv(timeout=5))
            start = time.perf_counter()
            for t, row in zip(times.tolist(), rows.tolist(), strict=True):
                time.sleep(max(0.0, start + t - time.perf_counter()))
                ws.send(json.dumps({"t": t, "v": row}))
                if done.is_set():
                    return

    sender = threading.Thread(target=stream, daemon=True)
    sender.start()
    try:  # the panel's text and its estimate, read in one go from the same draw
        estimate, text = live_page.wait_for(
            "document.querySelector('#saddle-estimate [data-lock=locked]') && "
            "[riderlive.saddle.estimate, document.getElementById('saddle-estimate').innerText]",
            timeout=8,
        )
    finally:
        done.set()
        sender.join(5)
    spec = GAIT_TABLE[Gait.TROT]
    assert estimate["gait"] == "trot"
    assert estimate["stride_hz"] == pytest.approx(spec.frequency_at(spec.default_speed), rel=0.03)
    assert "locked" in text and "gait trot" in text and " Hz" in text
    assert live_page.errors == []
