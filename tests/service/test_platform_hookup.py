"""The service drives a motion platform: the real server, the firmware's host build (the C
program) on a pty, the guardian.

- nothing moves at start; REST arms it by name, it follows the procedural trot within its
  limits; /api/devices, /api/platform and /metrics show its state, workspace use, limits and
  the link's counters; the cueing intensity is live (PATCH), bad values refused;
- a killed tick: the guardian opens the port (its HELLO parks the platform), the firmware
  parks and turns its outputs off, the tick comes back with the platform disarmed.
"""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import httpx
import pytest

from riderlive.platform.firmware_host import FirmwareHost
from tests.platform.test_device import accepted_targets as targets
from tests.service.live_server import LiveServer

TOKEN = "platform-token-1"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
NAME = "stewart_compact"


def wait_for(what: Callable[[], bool], timeout: float, say: Callable[[], object] = lambda: None) -> None:
    deadline = time.perf_counter() + timeout
    while time.perf_counter() < deadline:
        if what():
            return
        time.sleep(0.02)
    raise AssertionError(f"timed out: {say()}")


def platform(live: LiveServer) -> dict:
    response = live.get("/api/platform", headers=AUTH)
    return response.json() if response.status_code == 200 else {}


def wait_state(live: LiveServer, wanted: str, timeout: float = 20.0) -> None:
    wait_for(
        lambda: platform(live).get("state") == wanted,
        timeout,
        lambda: (wanted, platform(live).get("state"), live.log[-30:]),
    )


@pytest.fixture
def served(tmp_path: Path) -> Iterator[tuple[LiveServer, FirmwareHost]]:
    with FirmwareHost("platform6", trace=True) as firmware:
        config = (
            f'[tick]\nrate = 100.0\nrealtime_priority = false\n[security]\ntoken = "{TOKEN}"\n'
            f'[platform]\nfile = "{NAME}"\nport = "{firmware.port}"\n'
        )
        live = LiveServer(config, tmp_path, token=TOKEN)
        try:
            yield live, firmware
        finally:
            live.stop()
            assert "Traceback" not in "".join(live.log), "".join(live.log)


def post(live: LiveServer, path: str, body: dict | None = None) -> httpx.Response:
    return live.request("POST", path, json=body, headers=AUTH)


def test_the_service_drives_the_platform_and_the_guardian_parks_it(served: tuple[LiveServer, FirmwareHost]) -> None:
    live, firmware = served
    wait_state(live, "disarmed")
    time.sleep(0.5)  # the horse trots: nothing may move
    assert platform(live)["state"] == "disarmed" and not targets(firmware)
    assert firmware.status()["outputs_on"] == 0
    devices = live.get("/api/devices", headers=AUTH).json()
    assert [d["kind"] for d in devices["devices"]] == ["platform"] and devices["platform"]["name"] == NAME

    assert live.request("PATCH", "/api/platform", json={"intensity": 150}, headers=AUTH).status_code == 422
    assert live.request("PATCH", "/api/platform", json={"intensity": 60}).status_code == 401
    tuned = live.request("PATCH", "/api/platform", json={"intensity": 60, "by": "test"}, headers=AUTH)
    assert tuned.status_code == 200, tuned.text
    wait_for(lambda: platform(live)["platform"]["cueing"]["intensity"] == 60.0, 2.0)

    armed = post(live, "/api/arm", {"device": NAME, "by": "test"})
    assert armed.status_code == 200 and armed.json()["states"] == {NAME: "homing"}, armed.text
    wait_state(live, "running", 20.0)
    time.sleep(1.0)
    status = platform(live)
    body = status["platform"]
    assert body["firmware"]["state"] == "running" and 0.0 < body["workspace_use"] < 1.0
    assert len(body["actuators"]) == 6 and body["link"]["health"] == "ok"
    sent = targets(firmware)
    assert len(sent) > 50
    assert all(500 <= c <= 8000 for t in sent for c in t)  # the platform file's soft range, in counts
    assert live.metric("riderlive_device_state", f'device="{NAME}",state="running"') == 1
    assert live.metric("riderlive_platform_link_total", f'device="{NAME}",side="host",kind="rx_crc"') == 0
    assert live.metric("riderlive_platform_workspace_use", f'device="{NAME}"') > 0.0
    assert firmware.status()["counters"]["clipped"] == 0

    # the tick dies: the guardian takes the port, the firmware parks, outputs off
    pid = live.get("/api/devices", headers=AUTH).json()["supervision"]["tick_pid"]
    mark = len(firmware.events)
    os.kill(pid, signal.SIGKILL)
    firmware.wait_event(lambda e: e["event"] == "state" and e["to"] == "parking", 5.0, mark)
    firmware.wait_event(lambda e: e["event"] == "state" and e["to"] == "parked", 10.0, mark)
    # a new tick imports and loads the kernels again: seconds, tens of them on a saturated machine
    wait_for(lambda: live.get("/api/devices", headers=AUTH).json()["supervision"]["generation"] == 2, 60.0)
    wait_state(live, "disarmed", 60.0)  # back, and not re-armed
    assert firmware.status()["outputs_on"] == 0
    supervision = live.get("/api/devices", headers=AUTH).json()["supervision"]
    assert supervision["guardian"]["takeovers"] == 1
    assert "stopped, outputs off (read back)" in "".join(live.log)
