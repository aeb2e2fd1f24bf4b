"""The real server with ``--tail``: tail and braid channels published, finite, moving, recorded in takes,
and equal to an offline run of the same physics on the take's frames."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from websockets.sync.client import connect

from riderlive.channels import HORSE_NAMES, RIDER_NAMES, SADDLE_NAMES, is_known
from riderlive.framefile import read_frames
from riderlive.horse import DEFAULT_SCALE
from riderlive.physics.config import load_physics
from riderlive.physics.drive import FixedStepper, TakeSource
from riderlive.physics.outputs import publish
from riderlive.physics.skinned import SkinnedModel
from riderlive.realtime.edges import UnitEdges
from riderlive.realtime.tail import MAX_CATCH_UP, TickPhysics, physics_channels
from tests.realtime.test_tail import assert_matches_offline
from tests.service.conftest import BASE_CONFIG
from tests.service.live_server import LiveServer
from tests.service.test_publish import frames
from tests.waiting import wait_until

TAIL = physics_channels()


@pytest.fixture(scope="module")
def tail_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[LiveServer, dict]]:
    """A server with the tail on, recording from before its first tick."""
    live = LiveServer(BASE_CONFIG + "\n[physics]\ntail = true\n", tmp_path_factory.mktemp("tail"), wait_for_ticks=False)
    try:
        started = live.request("POST", "/api/record/start", json={"name": "from-start"}).json()
        live.wait_for_ticks()
        yield live, started
    finally:
        live.stop()


def test_hello_lists_the_tail_after_the_rider_and_frames_carry_it(tail_server: tuple[LiveServer, dict]) -> None:
    server, _ = tail_server
    with connect(server.ws + "/ws/rider") as ws:
        hello = json.loads(ws.recv(timeout=5))
        names = [c["name"] for c in hello["channels"]]
        assert names == [*RIDER_NAMES, *TAIL], "appended: version-1 clients keep their indices"
        assert all(is_known(n) for n in names)
        units = {c["name"]: c["unit"] for c in hello["channels"]}
        assert units["tail_10.tx"] == "length" and units["braid_03.rz"] == "deg"
        got = frames(ws, 120)[-100:]
        ws.send(json.dumps({"type": "subscribe", "channels": ["tail_10.tx", "head.rz"], "encoding": "binary"}))
        subset = [f for f in frames(ws, 40) if len(f["values"]) == 2]
    values = np.array([f["values"] for f in got])
    assert values.shape[1] == len(RIDER_NAMES) + len(TAIL)
    assert np.isfinite(values).all()
    tail = values[:, len(RIDER_NAMES) :]
    rz = [i for i, n in enumerate(TAIL) if n.startswith("tail_") and n.endswith(".rz")]
    assert tail[:, rz].std(axis=0).max() > 0.5, "the tail swings (deg) while the procedural horse trots"
    assert subset and np.isfinite(np.array([f["values"] for f in subset])).all()


def test_the_page_receives_the_tail_and_braid(tail_server: tuple[LiveServer, dict]) -> None:
    """The page groups ``tail_NN`` / ``braid_NN`` / ``*_cloth_NN`` from the hello, gets their values, draws flaps."""
    from riderlive.web import CHROMIUM, CHROMIUM_ARGS
    from tests.web.conftest import open_page

    if not Path(CHROMIUM).exists():
        pytest.fail(f"{CHROMIUM} is missing: apt-get install chromium (.ci/run does it)")
    from playwright.sync_api import sync_playwright

    server, _ = tail_server
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=list(CHROMIUM_ARGS))
        try:
            page = open_page(browser, server.base)
            page.wait_for("window.riderlive && riderlive.frames > 5 && 'braid_10.tx' in riderlive.values", 20.0)
            first = page.state("riderlive.values['tail_10.tx']")
            page.wait_for(f"riderlive.values['tail_10.tx'] !== {first!r}")
            page.wait_for("riderlive.clothFlaps === 2 && 'rt_cloth_10.tx' in riderlive.values", 10.0)
            names = page.state("[...document.querySelectorAll('#plot-add option')].map((o) => o.value)")
            assert page.errors == []
        finally:
            browser.close()
    assert set(TAIL) <= set(names), "every tail and braid channel can be plotted"


def test_take_records_the_tail_and_equals_an_offline_run(tail_server: tuple[LiveServer, dict]) -> None:
    server, _ = tail_server
    rows = lambda: server.get("/api/state").json()["recording"]["rows"]  # noqa: E731
    wait_until(lambda: rows() > 200, 20.0, rows)  # a second of ticks recorded
    state = server.get("/api/state").json()
    stopped = server.request("POST", "/api/record/stop").json()["take"]
    path = server.workdir / Path(stopped["path"])
    table = read_frames(path)
    assert table.names == (*HORSE_NAMES, *RIDER_NAMES, *TAIL, *SADDLE_NAMES), "the saddle's after the tail"
    meta = json.loads(path.with_suffix(".json").read_text())
    physics = state["tick"]["physics"]
    assert physics["channels"] == len(TAIL) and physics["errors"] == 0
    assert "riderlive_tick_physics_errors_total 0" in server.get("/metrics").text.splitlines()
    assert meta["engine_t0"] == physics["start"], "the take holds every tick since the physics started"
    data = table.values
    n_h, n_r = len(HORSE_NAMES), len(RIDER_NAMES)
    horse, rider, recorded = data[:, :n_h], data[:, n_h : n_h + n_r], data[:, n_h + n_r : n_h + n_r + len(TAIL)]
    times = table.times(200.0)  # engine_t - engine_t0: the physics' own clock, to the bit
    assert len(times) > 200 and np.isfinite(recorded).all()
    # Replayed as the tick saw it (each row known only from its own tick on, stalls
    # skipped past MAX_CATCH_UP steps as the take's times show), the take is the
    # physics to the bit: nothing lost, reordered or rounded between the tick and the file.
    replay = TickPhysics(None, UnitEdges(DEFAULT_SCALE))
    replayed = np.array([replay.tick(float(t), horse[i].tolist(), rider[i].tolist()) for i, t in enumerate(times)])
    assert replay.errors == 0
    assert np.array_equal(recorded, replayed), f"differs by {np.abs(recorded - replayed).max():.2e}"
    # An offline run that knows every row ahead (a bake) interpolates a hair past a
    # tick's time where the tick holds its frame; the first second stays within rounding
    # (tests/realtime/test_tail.py bounds it); the solver carries it on, so not the whole take.
    model = SkinnedModel.build(load_physics())
    second = times <= times[0] + 1.0
    source = TakeSource(times[second], horse[second], rider[second])
    stepper = FixedStepper(
        model.step, model.initial(source(times[0])), model.config.rate, start=float(times[0]), max_catch_up=MAX_CATCH_UP
    )
    offline = []
    for t in times[second]:
        stepper.advance_to(float(t), source)
        offline.append(publish(model, stepper.state))
    assert_matches_offline(recorded[second], np.array(offline), TAIL)
