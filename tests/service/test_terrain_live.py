"""``[source.terrain]``: the live service's procedural horse on a slope, and a change of ground live."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from riderlive.channels import HORSE_INDEX, RIDER_INDEX
from riderlive.horse.terrain import HOOF_BASE, TRANSITION
from riderlive.rules import RiderModel, load_preset
from tests.service.conftest import BASE_CONFIG
from tests.service.live_server import LiveServer
from tests.service.producers import Follower
from tests.waiting import wait_until

SLOPE = 8.0
GROUND = HORSE_INDEX["ground.rz"]
PITCH = HORSE_INDEX["rearPivot.rz"]
TX, TY = HORSE_INDEX["root.tx"], HORSE_INDEX["root.ty"]
LOWER_BACK = RIDER_INDEX["lower_back.rz"]
MODEL = RiderModel(params=load_preset("kuhnel2003"), scale=25.0)
HILL = BASE_CONFIG.replace(
    "[source]\nresume_after = 0.5\n",
    f'[source]\nresume_after = 0.5\nkind = "procedural"\ngait = "gallop"\n\n[source.terrain]\nslope = {SLOPE}\n',
)
assert HILL != BASE_CONFIG


@pytest.fixture(scope="module")
def hill(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    live = LiveServer(HILL, tmp_path_factory.mktemp("hill"))
    yield live
    live.stop()


def await_state(live: LiveServer, predicate: Any, timeout: float = 10.0) -> dict[str, Any]:
    """The first /api/state whose tick status satisfies ``predicate`` (polled: the status has no stream)."""
    tick: dict[str, Any] = {}

    def check() -> bool:
        nonlocal tick
        tick = live.get("/api/state").json()["tick"]
        return bool(predicate(tick))

    wait_until(check, timeout, lambda: tick, poll=0.02)
    return tick


def lean_of(horse: list[float]) -> float:
    """The rider's ``lower_back.rz`` on ``horse`` minus hers on the same horse on flat ground."""
    flat = list(horse)
    flat[PITCH] -= flat[GROUND]
    flat[GROUND] = 0.0
    return MODEL.evaluate(horse)[LOWER_BACK] - MODEL.evaluate(flat)[LOWER_BACK]


def test_the_live_horse_runs_up_the_configured_slope_and_the_rider_leans(hill: LiveServer) -> None:
    tick = hill.get("/api/state").json()["tick"]
    assert tick["terrain"] == {"kind": "slope", "slope": SLOPE, "from": 0.0}
    horse = hill.get("/api/horse").json()["terrain"]
    assert horse == {"max_slope": 30.0, "transition": TRANSITION}
    follower = Follower(hill.ws)
    try:
        follower.wait_for(lambda f: True)
        frames = follower.frames[:]
        follower.wait_for(lambda f: len(follower.frames) > len(frames) + 20)
        frames = follower.frames[-20:]
    finally:
        follower.close()
    for frame in frames:
        h = frame["horse"]
        assert h[GROUND] == pytest.approx(SLOPE, abs=1e-9)  # the chord under the hooves of a constant slope
        assert math.atan2(h[TY], h[TX]) == pytest.approx(math.radians(SLOPE), abs=1e-9)  # up the hill from (0, 0)
        np.testing.assert_allclose(frame["values"], MODEL.evaluate(h), rtol=0.0, atol=1e-9)
        # kuhnel2003 [terrain]: upright 1, uphill_lean 0.5: (1 + 0.5) * 8 = 12 deg on lower_back.rz
        assert lean_of(h) == pytest.approx(12.0, abs=1e-9)


def test_flat_by_default(server: LiveServer) -> None:
    """The shared server's config has no [source.terrain]: the horse of before, flat and level."""
    assert server.get("/api/state").json()["tick"]["terrain"] is None
    follower = Follower(server.ws)
    try:
        frame = follower.wait_for(lambda f: f["driver"] == "procedural", timeout=10)
    finally:
        follower.close()
    assert (
        frame["horse"][GROUND] == 0.0 and frame["horse"][TY] == 0.0 and frame["horse"][HORSE_INDEX["ground.ty"]] == 0.0
    )
    np.testing.assert_allclose(frame["values"], MODEL.evaluate(frame["horse"]), rtol=0.0, atol=1e-9)


def test_a_new_ground_applies_live_without_a_jump(hill: LiveServer) -> None:
    """PUT /api/source with a terrain: from the next tick, the ground under the horse stays and the
    slope eases over TRANSITION m into the new one; position and pitch never jump."""
    before = hill.get("/api/state").json()["source"]
    for body, where, why in (
        ({"slope": 45.0}, ["body", "procedural", "terrain", "slope"], "less than or equal to 30"),
        ({"slope": 5.0, "profile": [[0, 5]]}, ["body", "procedural", "terrain"], "exactly one of"),
        ({"profile": [[0, 0], [0, 5]]}, ["body", "procedural", "terrain", "profile"], "increase strictly"),
    ):
        reply = hill.request("PUT", "/api/source", json={"kind": "procedural", "terrain": body})
        assert reply.status_code == 422, reply.text
        detail = reply.json()["detail"][0]
        assert detail["loc"][: len(where)] == where and why in detail["msg"], detail
    assert hill.get("/api/state").json()["source"] == before
    follower = Follower(hill.ws)
    try:
        follower.wait_for(lambda f: True)
        reply = hill.request("PUT", "/api/source", json={"kind": "procedural", "terrain": {"slope": -6.0}})
        assert reply.status_code == 200
        assert reply.json()["terrain"] == {"slope": -6.0}
        tick = await_state(hill, lambda t: t["terrain"]["slope"] == -6.0)
        speed = tick["speed"]
        start = tick["terrain"]["from"]
        assert start > HOOF_BASE / 2 + TRANSITION
        down = follower.wait_for(lambda f: f["horse"][GROUND] == pytest.approx(-6.0, abs=1e-9), timeout=10)
        follower.wait_for(lambda f: f["seq"] > down["seq"] + 10)
        frames = [f for f in follower.frames if f["seq"] <= down["seq"] + 10]
    finally:
        follower.close()
    changed = next(i for i, f in enumerate(frames) if abs(f["horse"][GROUND] - SLOPE) > 1e-9)
    assert changed > 0, "the frames before the change are on the old slope"
    steps = 0
    for a, b in zip(frames, frames[1:]):
        if b["seq"] != a["seq"] + 1:
            continue  # a frame the follower missed: no step to measure
        steps += 1
        dt = b["t"] - a["t"]
        moved = math.hypot(b["horse"][TX] - a["horse"][TX], b["horse"][TY] - a["horse"][TY])
        assert moved <= speed * dt * 1.001 + 1e-9, (a["seq"], moved)  # along the ground at its speed
        # the slope changes by 14 deg over TRANSITION m: the pitch at most that per metre run
        turned = abs(b["horse"][GROUND] - a["horse"][GROUND])
        assert turned <= 14.0 / TRANSITION * speed * dt * 1.001 + 1e-9, (a["seq"], turned)
        np.testing.assert_allclose(b["values"], MODEL.evaluate(b["horse"]), rtol=0.0, atol=1e-9)
    assert steps >= 10
    # downhill: (1 + downhill_lean 0.1) * -6 = -6.6 deg on lower_back.rz
    assert lean_of(frames[-1]["horse"]) == pytest.approx(-6.6, abs=1e-9)
    assert frames[-1]["horse"][GROUND] == pytest.approx(-6.0, abs=1e-9)
