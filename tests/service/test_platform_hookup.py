"""The service drives a motion platform: the real server, the firmware's host build (the C
program) on a pty, the guardian.

- nothing moves at start; REST arms it by name, it follows the procedural trot within its
  limits; /api/devices, /api/platform and /metrics show its state, workspace use, limits and
  the link's counters; the cueing intensity is live (PATCH), bad values refused;
- a killed tick: the guardian opens the port (its HELLO parks the platform), the firmware
  parks and turns its outputs off, the tick comes back with the platform disarmed;
- a saddle point other than the default (``[saddle] forward = 0.9, up = 0.3``) and a
  service speaking decimetres: the platform follows the saddle the page is shown, in metres.
"""

from __future__ import annotations

import json
import os
import signal
from collections.abc import Callable, Iterator
from pathlib import Path

import httpx
import pytest

from riderlive.channels import HORSE_INDEX, HORSE_NAMES, SADDLE_NAMES
from riderlive.platform.firmware_host import FirmwareHost
from riderlive.saddle import SaddlePoint, saddle_from_horse
from tests.platform.test_device import accepted_targets as targets
from tests.service.live_server import LiveServer
from tests.service.producers import Follower, Producer, constant
from tests.waiting import wait_until

TOKEN = "platform-token-1"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
NAME = "stewart_compact"


def wait_for(what: Callable[[], bool], timeout: float, say: Callable[[], object] = lambda: None) -> None:
    wait_until(what, timeout, say, poll=0.02)


def device_ticks(live: LiveServer) -> int:
    return int(live.get("/api/devices", headers=AUTH).json()["devices"][0]["counters"]["ticks"])


def wait_ticks(live: LiveServer, ticks: int) -> None:
    """Until the platform has been ticked ``ticks`` more times (a span of the tick's own time)."""
    start = device_ticks(live)
    wait_for(lambda: device_ticks(live) >= start + ticks, 15.0, lambda: device_ticks(live))


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
def served(tmp_path: Path, request: pytest.FixtureRequest) -> Iterator[tuple[LiveServer, FirmwareHost]]:
    extra = getattr(request, "param", "")
    with FirmwareHost("platform6", trace=True) as firmware:
        config = (
            f'[tick]\nrate = 100.0\nrealtime_priority = false\n{extra}[security]\ntoken = "{TOKEN}"\n'
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
    wait_ticks(live, 50)  # the horse trots: nothing may move
    assert platform(live)["state"] == "disarmed" and not targets(firmware)
    assert firmware.status()["outputs_on"] == 0
    devices = live.get("/api/devices", headers=AUTH).json()
    assert [d["kind"] for d in devices["devices"]] == ["platform"] and devices["platform"]["name"] == NAME

    assert live.request("PATCH", "/api/platform", json={"intensity": 150}, headers=AUTH).status_code == 422
    assert live.request("PATCH", "/api/platform", json={"intensity": 60}).status_code == 401
    tuned = live.request("PATCH", "/api/platform", json={"intensity": 60, "by": "test"}, headers=AUTH)
    assert tuned.status_code == 200, tuned.text
    wait_for(lambda: platform(live)["platform"]["cueing"]["intensity"] == 60.0, 2.0)

    live.wait_guardian()
    armed = post(live, "/api/arm", {"device": NAME, "by": "test"})
    assert armed.status_code == 200 and armed.json()["states"] == {NAME: "homing"}, armed.text
    wait_state(live, "running", 20.0)
    wait_for(lambda: len(targets(firmware)) > 100, 10.0, lambda: len(targets(firmware)))
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


POINT = SaddlePoint(forward=0.9, up=0.3)
DECIMETRES = 2.5
"""``tick.length_scale`` of a service speaking decimetres (25 rig units per metre)."""
HORSE_M = {"rearPivot.ty": 0.04, "rearPivot.rz": 10.0, "rearPivot.rx": 3.0, "backMid.rz": -12.0}
"""A standing horse, hips 4 cm up, pitched 10 deg nose up, rolled 3 deg, the back bent 12 deg (m, deg)."""


SADDLE_POINT_TICK = f"length_scale = {DECIMETRES}\nspare = false\n[saddle]\nforward = 0.9\nup = 0.3\n"
"""``[tick]`` lines (and the saddle point) of the saddle-point test: it never fails over, so no spare."""


@pytest.mark.parametrize("served", [SADDLE_POINT_TICK], indirect=True)
def test_the_platform_follows_the_configured_saddle_point_in_metres(served: tuple[LiveServer, FirmwareHost]) -> None:
    live, _ = served
    horse = [0.0] * len(HORSE_NAMES)
    for name, value in HORSE_M.items():
        horse[HORSE_INDEX[name]] = value
    expected = saddle_from_horse(horse, POINT)  # m, deg
    default = saddle_from_horse(horse)
    assert max(abs(a - b) for a, b in zip(expected[:3], default[:3], strict=True)) > 0.01  # the bug: 1 cm here
    in_dm = {k: v * 10.0 if k.split(".")[1].startswith("t") else v for k, v in HORSE_M.items()}
    producer = Producer(live.ws, constant(in_dm), rate=100.0)
    follower = Follower(live.ws)
    follower.ws.send(json.dumps({"type": "subscribe", "saddle": True}))
    try:
        wait_state(live, "disarmed")
        live.wait_guardian()
        armed = post(live, "/api/arm", {"device": NAME, "by": "test"})
        assert armed.status_code == 200, armed.text
        wait_state(live, "running", 20.0)
        wait_for(
            lambda: platform(live)["platform"]["saddle"] == pytest.approx(expected, abs=1e-9),
            5.0,
            lambda: (platform(live)["platform"]["saddle"], expected),
        )
        # what the page is shown: the same saddle, in the service's unit (dm)
        shown = follower.wait_for(lambda f: f.get("driver") == "input" and "saddle" in f, 5.0)["saddle"]
        assert len(shown) == len(SADDLE_NAMES)
        assert [v / 10.0 for v in shown[:3]] + shown[3:] == pytest.approx(expected, abs=1e-9)
    finally:
        producer.close()
        follower.close()
