"""The previs page in a real headless Chromium against the real service."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest

from riderlive.channels import BY_NAME, HORSE_NAMES, RIDER_NAMES, Kind
from riderlive.horse import DEFAULT_SCALE, GAIT_TABLE, Gait
from riderlive.rules import RiderModel
from riderlive.skeleton import HORSE_RIG, bone_quaternions, horse_pose, rider_pose, rider_rig
from tests.waiting import wait_until
from tests.web.conftest import STATE_FPS, PageUnderTest, Server, open_page

pytestmark = pytest.mark.browser


def _recent(p: PageUnderTest, channel: str, seconds: float) -> list[float]:
    """Values of ``channel`` in the frames the page received over the last ``seconds``."""
    return list(p.state(f"riderlive.history({channel!r}, {seconds})"))


def test_page_loads_live_without_console_errors(live_page: PageUnderTest) -> None:
    live_page.wait_for("riderlive.fps > 0", timeout=5)
    assert live_page.state("riderlive.state") == "live"
    assert live_page.page.locator("#conn").inner_text() == "connected"
    # Nobody feeds /ws/horse: the procedural fallback drives, and the page says so.
    live_page.wait_for("riderlive.driverText === 'procedural — waiting for live input'", timeout=5)
    assert live_page.page.locator("#driver").inner_text() == "procedural — waiting for live input"
    assert live_page.page.locator("#rigstate").inner_text() == "no rig attached"
    assert live_page.page.locator("#estop").is_visible()
    assert live_page.page.locator("#gone").is_hidden()
    assert live_page.state("riderlive.errors") == []
    assert live_page.errors == []


def test_rider_pose_follows_the_frames_and_matches_the_python_skeleton(live_page: PageUnderTest) -> None:
    names = list(rider_rig().names)
    poses = []
    for _ in range(2):
        seq, values, pose, horse = live_page.state(
            "[riderlive.seq, riderlive.values, riderlive.pose.rider, riderlive.pose.horse]"
        )
        poses.append((seq, values, pose))
        # The page's pose is the Python skeleton's pose of the same frame (with the rider
        # parts, hands on the reins and feet in the stirrups, when the service publishes them).
        if live_page.state("riderlive.riderRigName") == "rider_tack":
            expected = np.array(rider_pose(values, tack=True).local_rotations)  # type: ignore[call-arg]
        else:
            expected = np.array(bone_quaternions(values)).reshape(-1, 4)
        got = np.array([pose[n] for n in names])
        assert np.allclose(got, expected, atol=1e-9)
        horse_values = {n: v for n, v in values.items() if n in HORSE_NAMES}
        assert len(horse_values) == len(HORSE_NAMES)  # the page subscribed to the horse too
        want = horse_pose(horse_values).local_rotations
        assert np.allclose([horse[b.name] for b in HORSE_RIG.bones], want, atol=1e-9)
        live_page.wait_for(f"riderlive.seq >= {seq} + 0.4 * riderlive.tickRate", timeout=30.0)  # a later frame
    (seq0, _, pose0), (seq1, _, pose1) = poses
    assert seq1 > seq0
    assert not np.allclose(pose0["lower_back"], pose1["lower_back"], atol=1e-6), "the rider did not move"


def test_latency_panel_shows_the_service_histograms(live_page: PageUnderTest) -> None:
    live_page.wait_for(
        "riderlive.latency.latest !== null && riderlive.latency.latest.histograms.tick_lateness.window.count > 0",
        timeout=10,
    )
    answer, rows = live_page.page.evaluate(
        """() => [riderlive.latency.latest, [...document.querySelectorAll('#latency tbody tr')].map(
            (r) => [r.dataset.key, r.hidden, [...r.children].map((c) => c.textContent)])]"""
    )
    shown = {key: (hidden, cells) for key, hidden, cells in rows}
    window = answer["histograms"]["tick_lateness"]["window"]
    assert shown["tick_lateness"][1][1:] == [f"{window[k] * 1e3:.2f}" for k in ("p50", "p99", "max")] + [
        str(window["count"])
    ]
    assert shown["ingest_to_wire"][0], "no rig: its row is hidden"
    goal = live_page.page.locator("#latency-goal").inner_text()
    assert goal == f"goal p99 ≤ {(answer['tick_period'] + 0.001) * 1e3:.2f} ms"
    lock = answer["phase_lock"]  # on by default; the page's test server has no producer
    assert lock is not None and not lock["locked"]
    assert live_page.page.locator("#latency-phase").inner_text() == "· tick not locked"


def _wait_estop(server: Server, engaged: bool, what: str) -> None:
    wait_until(lambda: bool(server.get("/api/state")["tick"].get("estop")) is engaged, 5.0, what, poll=0.05)


def test_estop_button_reaches_the_service(live_page: PageUnderTest, server: Server) -> None:
    assert server.get("/api/state")["tick"].get("estop") is not True
    live_page.page.locator("#estop").click()
    _wait_estop(server, True, "the e-stop never reached the service")
    live_page.wait_for("document.getElementById('estop').classList.contains('engaged')", timeout=5)
    # It says that it is latched, and what it stopped: here, nothing (no rig).
    live_page.wait_for("!document.getElementById('estop-state').hidden", timeout=5)
    shown = live_page.page.locator("#estop-state").inner_text()
    assert "E-STOP LATCHED" in shown and "no rig attached" in shown, shown
    live_page.page.locator("#reset").click()
    _wait_estop(server, False, "reset did not clear the e-stop")
    live_page.wait_for("document.getElementById('estop-state').hidden", timeout=5)
    assert not live_page.page.locator("#estop").evaluate("b => b.classList.contains('engaged')")


def test_space_bar_is_an_estop_and_never_presses_the_focused_button(live_page: PageUnderTest, server: Server) -> None:
    live_page.page.locator("#rec-start").focus()
    live_page.page.keyboard.press("Space")
    _wait_estop(server, True, "the space bar did not e-stop")
    seq = live_page.state("riderlive.seq")
    live_page.wait_for(f"riderlive.seq >= {seq} + 0.3 * riderlive.tickRate", timeout=30.0)  # time for a click to land
    assert server.get("/api/state")["recording"] is None, "the space bar also pressed the focused Record button"
    live_page.page.locator("#reset").click()
    _wait_estop(server, False, "reset did not clear the e-stop")


def _move_slider(p: PageUnderTest, key: str, value: float) -> None:
    p.page.evaluate(
        """([key, value]) => {
            const input = document.querySelector(`#params input[data-key="${key}"]`);
            input.value = value;
            input.dispatchEvent(new Event("input", { bubbles: true }));
        }""",
        [key, value],
    )


def test_weight_slider_changes_the_next_frames(live_page: PageUnderTest, server: Server) -> None:
    key = "knees.lift_offset"
    before_param = server.get("/api/params")[key]
    live_page.wait_for(f"document.querySelector('#params input[data-key=\"{key}\"]') !== null")
    live_page.wait_for("riderlive.history('lf_knee.ty', 2).length > 100", timeout=10)
    before = _recent(live_page, "lf_knee.ty", 1.0)
    _move_slider(live_page, key, before_param - 2.0)
    reached = lambda: server.get("/api/params")[key] == pytest.approx(before_param - 2.0, abs=0.02)  # noqa: E731
    wait_until(reached, 5.0, "the slider never reached the service", poll=0.05)
    seq = live_page.state("riderlive.seq")
    # the change blends in over tick.param_blend_time (0.5 s), then a second of frames
    live_page.wait_for(f"riderlive.seq >= {seq} + 1.7 * riderlive.tickRate", timeout=15.0)
    after = _recent(live_page, "lf_knee.ty", 1.0)
    try:
        assert len(before) > 30 and len(after) > 30
        # lift_offset is in thesis units; the service speaks metres (its default length scale).
        scale = DEFAULT_SCALE
        shift = np.median(after) - np.median(before)
        assert shift == pytest.approx(-2.0 / scale, abs=0.01)
        assert max(after) < min(before)
    finally:
        server.request("PATCH", "/api/params", {key: before_param})


def test_record_button_makes_a_take_that_replays_from_the_list(live_page: PageUnderTest, server: Server) -> None:
    page: Any = live_page.page
    page.locator("#rec-start").click()
    live_page.wait_for("document.getElementById('rec-now').textContent.startsWith('recording')", timeout=5)
    seq = live_page.state("riderlive.seq")
    live_page.wait_for(f"riderlive.seq >= {seq} + 0.6 * riderlive.tickRate", timeout=30.0)  # some frames recorded
    page.locator("#rec-stop").click()
    live_page.wait_for("document.getElementById('rec-now').textContent === ''", timeout=5)
    names = [t["name"] for t in server.get("/api/takes")["takes"]]
    assert names, "no take was recorded"
    row = f"#takes li[data-take='{names[0]}']"
    live_page.wait_for(f'document.querySelector("{row}") !== null')
    seq = live_page.state("riderlive.seq")
    page.locator(f"{row} .take-replay").click()
    try:
        replaying = lambda: server.get("/api/state")["source"].get("take") == names[0]  # noqa: E731
        wait_until(replaying, 10.0, "clicking the recorded take did not replay it", poll=0.05)
        live_page.wait_for(f"riderlive.seq > {seq} + 30", timeout=5)  # frames keep coming
    finally:
        server.request("PUT", "/api/source", {"kind": "live"})


def test_a_take_replays_on_the_page(live_page: PageUnderTest, server: Server) -> None:
    """A take in the service's takes directory, replayed from the page's list, drives the page."""
    frame = dict.fromkeys(HORSE_NAMES, 0.0)
    frame.update({"rearPivot.rz": 7.5, "backMid.rz": -4.0, "lfHoof.ty": 0.05})
    takes = server.workdir / "takes"
    takes.mkdir(exist_ok=True)
    rows = [",".join(["t", *HORSE_NAMES])]
    rows += [",".join([f"{k / 120:.6f}", *(repr(frame[n]) for n in HORSE_NAMES)]) for k in range(120 * 6)]
    (takes / "page-test-take.csv").write_text("\n".join(rows) + "\n")
    expected = dict(zip(RIDER_NAMES, RiderModel(scale=DEFAULT_SCALE).evaluate([frame[n] for n in HORSE_NAMES])))

    live_page.wait_for("document.querySelector('#takes li[data-take=\"page-test-take\"]') !== null")
    live_page.page.locator("#takes li[data-take='page-test-take'] .take-replay").click()
    try:
        live_page.wait_for("Math.abs(riderlive.values['rearPivot.rz'] - 7.5) < 1e-9", timeout=30)  # a busy host
        state = server.get("/api/state")["source"]
        assert state.get("kind") == "replay" and state.get("take") == "page-test-take"
        values = live_page.state("riderlive.values")
        assert values["backMid.rz"] == pytest.approx(-4.0)
        # The rider the page shows is the rules' rider for the take's horse, once the
        # service's blend from the previous source has settled.
        live_page.wait_for(f"Math.abs(riderlive.values['lower_back.rz'] - {expected['lower_back.rz']!r}) < 1e-6", 30)
        values = live_page.state("riderlive.values")
        for name in ("lower_back.rz", "cog.ty", "head.rz", "lf_foot.tx"):
            assert values[name] == pytest.approx(expected[name], abs=1e-9), name
        live_page.wait_for("document.getElementById('src-now').textContent.includes('page-test-take')", timeout=30)
    finally:
        server.request("PUT", "/api/source", {"kind": "live"})
    assert live_page.errors == []


def test_the_speed_slider_spans_the_chosen_gait_and_applies(live_page: PageUnderTest, server: Server) -> None:
    """A walk cannot be asked at a trot's speed from the page (the service would refuse it)."""
    page = live_page.page
    slider = "(() => { const s = document.getElementById('src-speed'); return [+s.min, +s.max, +s.value]; })()"
    page.select_option("#src-kind", "procedural")
    for gait, spec in GAIT_TABLE.items():
        page.select_option("#src-gait", gait.value)
        live_page.wait_for(f"+document.getElementById('src-speed').max === {spec.speed[1]!r}")
        assert live_page.state(slider) == [spec.speed[0], spec.speed[1], spec.default_speed], gait
    page.select_option("#src-gait", "walk")
    try:
        page.locator("#src-apply").click()
        live_page.wait_for("document.getElementById('src-now').textContent.includes('walk')", timeout=5)
        walk = GAIT_TABLE[Gait.WALK].default_speed
        assert server.get("/api/state")["source"] == {"kind": "procedural", "gait": "walk", "speed": walk}
    finally:
        server.request("PUT", "/api/source", {"kind": "live"})
    assert live_page.errors == []


def test_views_switch_the_camera(live_page: PageUnderTest) -> None:
    spots = {"default": live_page.state("riderlive.camera")}
    for view in ("side", "front", "perspective", "rear", "rider", "top"):
        live_page.page.locator(f"[data-view={view}]").click()
        spots[view] = live_page.state("riderlive.camera")
    # Every preset is its own; "side" is not the view the page opens with.
    assert len({tuple(np.round(v, 3)) for k, v in spots.items() if k != "default"}) == 6
    assert not np.allclose(spots["side"], spots["default"], atol=0.1)
    side, front = np.array(spots["side"]), np.array(spots["front"])
    assert abs(side[2]) > 3 * abs(side[0])  # looks along z: at the horse's flank
    assert abs(front[0]) > 3 * abs(front[2])  # looks along x: at the horse's chest


def test_servo_table_shows_the_rig_status(live_page: PageUnderTest) -> None:
    """A status message shaped like the rig's ``RigStatus.to_dict()`` fills the servo table."""
    assert live_page.page.locator("#rig").is_hidden()  # no rig attached to this service
    rig = {
        "state": "running",
        "fault": None,
        "servos": [
            {
                "name": "lower_back",
                "id": 1,
                "goal_deg": 12.5,
                "present_deg": 11.0,
                "tracking_error_deg": 1.5,
                "temperature_c": 41,
                "hardware_error": [],
            },
            {
                "name": "head<b>",
                "id": 2,
                "goal_deg": -3.0,
                "present_deg": None,
                "tracking_error_deg": None,
                "temperature_c": 77,
                "hardware_error": ["overheating"],
            },
        ],
    }
    # Handle the message and read the table in the same turn, before any real status arrives.
    shown = live_page.page.evaluate(
        """(rig) => {
            riderlive.link.handle({type: "status", estop: false, rig});
            const rows = [...document.querySelectorAll("#servos tbody tr")];
            return {
                visible: !document.getElementById("rig").hidden,
                rows: rows.map((r) => [...r.cells].map((c) => c.textContent)),
                classes: rows.map((r) => r.className),
                state: document.getElementById("rigstate").textContent,
            };
        }""",
        rig,
    )
    assert shown["visible"]
    assert shown["rows"] == [
        ["lower_back", "12.5", "11.0", "41.0", "—"],
        ["head<b>", "-3.0", "—", "77.0", "overheating"],  # names are shown as text, not markup
    ]
    assert shown["classes"] == ["", "fault"]
    assert shown["state"] == "rig: running"


def test_page_sends_the_control_token_and_reconnects_to_a_restarted_service(browser: Any, tmp_path: Any) -> None:
    """A service set up otherwise: a control token, and lengths in thesis units (length_scale 1)."""
    token = "page-test-token-0123"
    config = f'[security]\ntoken = "{token}"\nrequire_token = true\n\n[tick]\nlength_scale = 1.0\n'
    s = Server(0, tmp_path, extra_config=config)
    try:
        s.start()
        without = open_page(browser, s.url, max_fps=STATE_FPS)
        # publishing stays open; a just started service's first frames (a busy host: 60 s)
        without.wait_for("riderlive.connected && riderlive.frames > 5", timeout=60)
        # An e-stop is never locked (auth.Rule.NEVER_LOCKED): it latches without the token;
        # the reset, a write that needs it, is refused, and the page says why.
        devices = lambda: s.get("/api/devices")  # noqa: E731
        estop = lambda: devices()["estop"]  # noqa: E731  (the latch, as the service reports it)
        without.page.locator("#estop").click()
        wait_until(estop, 5.0, "an e-stop without the token was not latched", poll=0.05)
        without.page.locator("#reset").click()
        without.wait_for("document.getElementById('message').textContent.includes('control token')", timeout=5)
        assert estop() is True
        without.page.close()

        p = open_page(browser, s.url, f"/#token={token}", max_fps=STATE_FPS)
        p.wait_for("riderlive.connected && riderlive.frames > 5", timeout=60)
        assert p.state("location.hash") == ""  # the token leaves the address bar
        # Lengths arrive in thesis units; the page poses the metre skeleton with value / 25.
        values, pose = p.state("[riderlive.values, riderlive.pose.rider]")
        metres = {n: v / DEFAULT_SCALE if BY_NAME[n].kind is Kind.TRANSLATION else v for n, v in values.items()}
        if p.state("riderlive.riderRigName") == "rider_tack":
            want = np.array(rider_pose(metres, tack=True).local_rotations)  # type: ignore[call-arg]
        else:
            want = np.array(bone_quaternions({n: metres[n] for n in RIDER_NAMES})).reshape(-1, 4)
        assert np.allclose([pose[n] for n in rider_rig().names], want, atol=1e-9)
        first = p.state("riderlive.session")

        # The service goes away: the page says so, then finds the restarted one by itself.
        s.stop()
        p.wait_for("riderlive.state === 'gone'", timeout=5)
        assert p.page.locator("#gone").is_visible()
        assert p.page.locator("#conn").inner_text() == "service gone"
        s.start()
        p.wait_for(f"riderlive.connected && riderlive.session !== {first!r}", timeout=15)
        assert p.page.locator("#gone").is_hidden()

        # The token survived the reconnect: the reset, which needs it, clears the new service's e-stop.
        p.page.locator("#estop").click()
        wait_until(estop, 5.0, lambda: f"the e-stop never reached the restarted service: {devices()}", poll=0.05)
        # The reset needs the tick (503 while it starts): the page is live before the tick beats.
        up = lambda: devices()["supervision"]["up"]  # noqa: E731
        wait_until(up, 30.0, lambda: f"the tick never came up: {devices()}", poll=0.1)
        p.page.locator("#reset").click()
        said = lambda: p.state("document.getElementById('message').textContent")  # noqa: E731
        wait_until(
            lambda: estop() is False,
            10.0,
            lambda: f"the reset never cleared the e-stop; the page: {said()!r}",
            poll=0.05,
        )
        p.page.close()
    finally:
        s.stop()


def test_arm_and_disarm_sit_by_the_estop_and_name_the_rig(live_page: PageUnderTest, server: Server) -> None:
    """A status of a disarmed rig enables Arm; Arm posts the rig's name (this service has no
    rig: it refuses, and the page says so); a running rig enables Disarm instead."""
    page = live_page.page
    with page.expect_request(lambda r: r.url.endswith("/api/arm")) as request:
        # The click in the same turn as the status: the service's own status (no rig) hides
        # Arm again when it arrives, which on a busy host was before a separate click landed.
        shown = page.evaluate(
            """() => {
                const rig = {name: "bench3", state: "disarmed", servos: []};
                riderlive.link.handle({type: "status", estop: false, rig});
                const b = (id) => document.getElementById(id);
                const out = {arm: !b("arm").hidden && !b("arm").disabled, disarm: b("disarm").disabled,
                             state: b("rigstate").textContent};
                b("arm").click();
                return out;
            }"""
        )
    assert shown == {"arm": True, "disarm": True, "state": "bench3: disarmed"}
    assert json.loads(request.value.post_data or "{}") == {"device": "bench3", "by": "page"}
    live_page.wait_for("document.getElementById('message').textContent.includes('no device')", timeout=30)
    running = page.evaluate(
        """() => {
            riderlive.link.handle({type: "status", estop: false, rig: {name: "bench3", state: "running", servos: []}});
            return [document.getElementById("arm").disabled, document.getElementById("disarm").disabled];
        }"""
    )
    assert running == [True, False]


def test_the_platform_is_drawn_with_its_actuators_coloured_by_closeness(live_page: PageUnderTest) -> None:
    """A status with the platform's real ``status()`` (one actuator at its soft limit) fills the
    platform panel and draws base, top and actuators in the 3D view."""
    from riderlive.platform.device import PlatformPlug
    from riderlive.platform.mechanism.pipeline import PlatformModel

    assert live_page.page.locator("#platform").is_hidden()  # no platform attached to this service
    plug = PlatformPlug(PlatformModel.load("stewart_compact"), "/dev/null")
    plug.positions = [plug.model.geometry.lower[0], *plug.model.home_positions[1:]]
    platform = {"name": plug.name, "state": "running", "detail": "", "fault": None, **plug.status()}
    shown = live_page.page.evaluate(
        """(platform) => {
            riderlive.link.handle({type: "status", estop: false, platform});
            const rows = [...document.querySelectorAll("#platform-actuators tbody tr")];
            const g = riderlive.platform.geometry;
            return {
                visible: !document.getElementById("platform").hidden,
                closeness: rows.map((r) => Number(r.dataset.closeness)),
                target: rows.map((r) => r.cells[1].textContent),
                state: document.getElementById("platform-state").textContent,
                drawn: riderlive.platform.group.visible,
                points: g.getAttribute("position").count,
                firstLeg: Array.from(g.getAttribute("color").array.slice(12, 15)),
            };
        }""",
        platform,
    )
    assert shown["visible"] and shown["drawn"]
    home = plug.status()["platform"]["actuators"][1]["closeness"]  # home is 40.4 mm, mid-range 42.5
    assert shown["closeness"][0] == 1.0 and shown["closeness"][1:] == [pytest.approx(home, abs=1e-3)] * 5
    assert shown["target"][0] == "5.0"  # mm of stroke at the soft minimum
    assert shown["state"].startswith("stewart_compact: running")
    assert shown["points"] == 6 * 3 * 2  # per actuator: a base edge, a top edge, the actuator
    red, green, _ = shown["firstLeg"]
    assert red > 0.8 and green < 0.2  # at its limit: red


def test_maxfps_caps_the_draws_and_the_state_follows_every_frame(live_page: PageUnderTest) -> None:
    """``?maxfps=N`` (this module's page): at most N draws a second of the frames coming in at
    the tick's rate, while ``riderlive.values`` is the newest frame's at every animation frame
    and a snapshot still comes with the next draw."""
    p = live_page
    assert p.state("riderlive.maxFps") == STATE_FPS
    draws, frames, t0 = p.state("[riderlive.draws, riderlive.frames, performance.now()]")
    p.wait_for(f"riderlive.draws >= {draws} + 10", timeout=30)
    draws1, frames1, t1 = p.state("[riderlive.draws, riderlive.frames, performance.now()]")
    seconds = (t1 - t0) / 1000
    assert draws1 - draws <= seconds * STATE_FPS + 1, (draws1 - draws, seconds)
    assert frames1 - frames > 2 * (draws1 - draws), "fewer frames came in than the cap: nothing was capped"
    # Read in an animation frame after the page's own: its values are the last frame received.
    newest = p.page.evaluate(
        """() => new Promise((done) => requestAnimationFrame(() => {
            const h = riderlive.history('cog.ty', 1);
            done([riderlive.values['cog.ty'], h[h.length - 1]]); // oldest first
        }))"""
    )
    assert newest[0] == newest[1]
    shot = p.page.evaluate("riderlive.snapshot()")
    assert shot["width"] > 0 and shot["image"].startswith("data:image/png")
