"""What a previs user sees, in a real headless Chromium against the real service:
the skinned horse and rider (pelvis in the saddle through a jump), camera views that
differ, grouped weights with a working filter, honest e-stop and device lines, plots
with units and a window, the take browser (bake, download), and the page without WebGL 2."""

from __future__ import annotations

import base64
import io
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

from riderlive.channels import HORSE_NAMES, RIDER_NAMES
from riderlive.framefile import read_frames
from riderlive.horse import DEFAULT_SCALE
from riderlive.rules import RiderModel
from tests.web.conftest import PageUnderTest, Server, open_page

pytestmark = pytest.mark.browser

PELVIS = (0, 255, 0)
SADDLE = (255, 0, 0)
PELVIS_TO_SADDLE_M = 0.2
"""The pelvis' centre sits 7.5 cm above the seat at rest and the rules lift it by at most
cog.ty (about 5 cm in the jump): its drawn centre stays within this of the saddle's."""


@pytest.fixture(scope="module")
def live_page(browser: Any, server: Server) -> Iterator[PageUnderTest]:
    """The page drawing every frame it gets: these tests look at its pixels."""
    p = open_page(browser, server.url)
    p.wait_for("window.riderlive && riderlive.connected && riderlive.frames > 5", timeout=40)
    yield p
    p.page.close()


def snapshot(p: PageUnderTest) -> tuple[np.ndarray, dict[str, Any]]:
    """The 3D view's pixels right after the page drew a frame, and the poses it drew."""
    return decoded(p.page.evaluate("riderlive.snapshot()"))


def decoded(shot: dict[str, Any]) -> tuple[np.ndarray, dict[str, Any]]:
    """A page snapshot's PNG data URL as RGB pixels, and the rest of the snapshot."""
    png = base64.b64decode(shot.pop("image").split(",", 1)[1])
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int), shot


def snapshots_when(p: PageUnderTest, tests: list[str], timeout: float = 10.0) -> str:
    """Ask the page for the view of the first frame whose values pass each test (a JS
    expression of ``v``); returns the page-side name to await with :func:`shots_of`.

    The page checks every frame it receives and queues each matching one to be drawn
    next, so a pose that lasts a few ticks is caught at any drawing rate (a loaded host
    draws a few frames/s) and the requests, made up front, never miss an early one.
    """
    asks = ", ".join(f"riderlive.snapshotWhen((v) => {t}, {timeout * 1000:.0f})" for t in tests)
    p.page.evaluate(f"() => {{ riderlive.pendingShots = Promise.all([{asks}]); }}")
    return "riderlive.pendingShots"


def shots_of(p: PageUnderTest, name: str) -> list[tuple[np.ndarray, dict[str, Any]]]:
    return [decoded(shot) for shot in p.page.evaluate(name)]


def scene_pixels(p: PageUnderTest) -> np.ndarray:
    return snapshot(p)[0]


def centroid(img: np.ndarray, rgb: tuple[int, int, int]) -> tuple[np.ndarray, int]:
    mask = (np.abs(img - np.array(rgb)) < 40).all(axis=2)
    ys, xs = np.nonzero(mask)
    return (np.array([xs.mean(), ys.mean()]) if len(xs) else np.array([np.nan, np.nan])), len(xs)


def test_each_camera_view_looks_different(live_page: PageUnderTest) -> None:
    p = live_page
    p.state("riderlive.setRenderScale(0.5)")  # half the pixels: enough to tell views apart
    shots = {}
    for view in ("perspective", "side", "front", "rear", "rider", "top"):
        p.page.locator(f"[data-view={view}]").click()
        p.wait_for(f"riderlive.viewName === {view!r}")  # the camera moves at once (scene.js setView)
        shots[view] = scene_pixels(p)  # the next frame drawn: from the new camera
    names = list(shots)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            differ = np.abs(shots[a] - shots[b]).max(axis=2) > 30
            assert differ.mean() > 0.05, f"views {a} and {b} look the same ({differ.mean():.3f} of pixels differ)"
    p.state("riderlive.setRenderScale(null)")
    p.page.locator("[data-view=perspective]").click()


def test_pelvis_stays_in_the_saddle_through_a_jump(live_page: PageUnderTest, server: Server) -> None:
    """Side view, flat part colours: the pelvis' pixels stay by the saddle's while the horse jumps."""
    p = live_page
    server.request("PUT", "/api/source", {"kind": "procedural", "gait": "canter", "speed": 6.0})
    try:
        p.state("riderlive.setRenderScale(1)")
        p.page.locator("[data-view=side]").click()
        p.state("riderlive.setIdColors(true)")
        p.wait_for("riderlive.horseText && riderlive.horseText.startsWith('horse: canter')", timeout=15)
        conds = [
            "v['rearPivot.rz'] > 12",  # take-off
            "v['hip.rz'] > 15",  # over the fence, folded forward from the hip ([jump] layer)
            "v['rearPivot.rz'] < -10",  # landing
        ]
        pending = snapshots_when(p, conds)
        server.request("POST", "/api/horse/perform", {"move": "jump"})
        seen = []
        for cond, (img, shot) in zip(conds, shots_of(p, pending), strict=True):
            assert p.page.evaluate(f"(v) => {cond}", shot["values"]), cond  # the pose drawn is the one asked for
            seen.append((cond, img, (shot["horseWorld"]["saddle"], shot["riderWorld"]["hips"])))
        gaps: list[float] = []
        for cond, img, (saddle, hips) in seen:
            pelvis, n_pelvis = centroid(img, PELVIS)
            seat, n_saddle = centroid(img, SADDLE)
            assert n_pelvis > 30 and n_saddle > 30, (cond, n_pelvis, n_saddle)
            top = np.array(p.state(f"riderlive.project([{saddle[0]}, {saddle[1] + 1}, {saddle[2]}])"))
            px_per_m = float(np.linalg.norm(top - np.array(p.state(f"riderlive.project({saddle})"))))
            gap = float(np.linalg.norm(pelvis - seat)) / px_per_m
            assert gap < PELVIS_TO_SADDLE_M, f"{cond}: pelvis {gap:.3f} m from the saddle"
            gaps.append(gap)
            # The skeleton agrees: the hips joint is 0.10 m + cog.ty above the seat.
            assert np.linalg.norm(np.subtract(hips, saddle)) < 0.2
        print("pelvis to saddle (m):", [round(g, 3) for g in gaps])
    finally:
        p.state("riderlive.setIdColors(false)")
        p.state("riderlive.setRenderScale(null)")
        p.page.locator("[data-view=perspective]").click()
        server.request("PUT", "/api/source", {"kind": "live"})


def test_hands_hold_the_reins_and_feet_are_in_the_stirrups(live_page: PageUnderTest) -> None:
    """The reins run from the bit to the hands and the leathers from the saddle to the irons:
    the horse's tack bones when its skeleton has them, else the page's own (the corners of
    the mouth, an iron under the ball of each foot)."""
    tack, rider, horse, bones = live_page.state(
        "[riderlive.tack, riderlive.pose.riderWorld, riderlive.pose.horseWorld, riderlive.tackBones]"
    )
    for side, long in (("lf", "left"), ("rt", "right")):
        mouth, grip = tack[f"{side}_rein"]
        assert np.linalg.norm(np.subtract(grip, rider[f"{side}_hand"])) < 0.1
        assert mouth[0] > grip[0] + 0.3  # the bit is well in front of the hands
        bar, iron = tack[f"{side}_stirrup"]
        assert bar[1] > iron[1] + 0.3  # the leather hangs from the saddle
        if bones["reinBones"]:
            assert np.allclose(mouth, horse[f"{long}Rein"], atol=1e-9)
        if bones["stirrupBones"]:
            assert np.allclose(iron, horse[f"{long}Stirrup"], atol=1e-9)
            assert np.allclose(bar, horse[f"{long}StirrupBar"], atol=1e-9)
        else:
            ball = np.add(rider[f"{side}_foot"], rider[f"{side}_toes"]) / 2
            assert np.linalg.norm(np.subtract(iron, ball)) < 0.05


VISIBLE_WEIGHTS = (
    "[...document.querySelectorAll('#params label[data-key]')]"
    ".filter((l) => l.offsetParent !== null).map((l) => l.dataset.key)"
)


def test_weights_are_grouped_by_equation_with_full_names_and_filter(live_page: PageUnderTest, server: Server) -> None:
    p = live_page
    p.wait_for("document.querySelectorAll('#params label[data-key]').length > 50")
    groups = p.state("[...document.querySelectorAll('#params details[data-group]')].map((d) => d.dataset.title)")
    numbers = [int(t.split("Eq. ")[1].split("-")[0].split(" ")[0].rstrip(":")) for t in groups if "Eq. " in t]
    assert numbers == sorted(numbers) and numbers[0] == 1, groups
    keys = p.state("[...document.querySelectorAll('#params label[data-key]')].map((l) => l.dataset.key)")
    assert sorted(keys) == sorted(server.get("/api/params"))
    # Full names: the text is the whole key and nothing is cut off.
    cut = p.state(
        "[...document.querySelectorAll('#params label[data-key] span')]"
        ".filter((s) => s.textContent !== s.parentElement.dataset.key || s.scrollWidth > s.clientWidth + 1).length"
    )
    assert cut == 0
    p.page.locator("#param-filter").fill("lift_gain")
    visible = p.state(VISIBLE_WEIGHTS)
    assert visible and all("lift_gain" in k for k in visible), visible
    assert p.page.locator("#params label[data-key='waist.gain']").is_hidden()
    p.page.locator("#param-filter").fill("12")  # an equation number: the wrists (Eq. 12-13)
    visible = p.state(VISIBLE_WEIGHTS)
    assert visible and all(k.startswith("wrists.") for k in visible), visible
    p.page.locator("#param-filter").fill("")
    assert p.page.locator("#params label[data-key='waist.gain']").is_visible()


def test_estop_line_names_the_devices_it_stopped_and_arm_waits_for_reset(live_page: PageUnderTest) -> None:
    shown = live_page.page.evaluate(
        """() => {
            const dev = {name: "bench3", kind: "dynamixel", state: "estop", outputs_off_confirmed: true};
            riderlive.link.handle({type: "status", estop: true, devices: [dev]});
            const b = (id) => document.getElementById(id);
            const out = {line: b("estop-state").textContent, shown: !b("estop-state").hidden,
                         engaged: b("estop").classList.contains("engaged"), arm: b("arm").disabled,
                         panel: b("devices").textContent};
            riderlive.link.handle({type: "status", estop: false, devices: []});
            out.after = [b("estop-state").hidden, b("rigstate").textContent];
            return out;
        }"""
    )
    assert shown["shown"] and shown["engaged"] and shown["arm"]
    assert "E-STOP LATCHED" in shown["line"] and "bench3 (estop, outputs off confirmed)" in shown["line"]
    assert "bench3 (dynamixel): estop" in shown["panel"]
    assert shown["after"] == [True, "no rig attached"]


def test_plots_have_units_a_window_and_readable_lanes(live_page: PageUnderTest) -> None:
    p = live_page
    units = p.state("[riderlive.plots.units['lower_back.rz'], riderlive.plots.units['cog.ty']]")
    assert units == ["°", "m"]
    p.page.locator("#plot-window").select_option("30")
    assert p.state("riderlive.plots.window") == 30
    lanes = p.state("riderlive.plots.chosen.length")
    height = p.state("document.getElementById('plot').height")
    assert lanes >= 4 and height / lanes >= 64  # the time axis has its own canvas (#plot-axis)
    p.page.locator("#plot-own").uncheck()
    assert p.state("riderlive.plots.ownScale") is False
    p.page.locator("#plot-own").check()
    p.page.locator("#plot-window").select_option("10")


def test_take_browser_bakes_and_downloads(live_page: PageUnderTest, server: Server, tmp_path: Path) -> None:
    page: Any = live_page.page
    server.request("POST", "/api/record/start", {"name": "browse-me"})
    live_page.wait_for("riderlive.frames > 0")
    seq = live_page.state("riderlive.seq")
    live_page.wait_for(f"riderlive.seq >= {seq} + 0.5 * riderlive.tickRate", timeout=30.0)  # half a second recorded
    server.request("POST", "/api/record/stop")
    row = "#takes li[data-take='browse-me']"
    live_page.wait_for(f'document.querySelector("{row}") !== null')
    with page.expect_download() as got:
        page.locator(f"{row} .take-download").click()
    got.value.save_as(tmp_path / "take.csv")
    assert (tmp_path / "take.csv").read_bytes() == (server.workdir / "takes" / "browse-me.csv").read_bytes()
    page.locator(f"{row} .take-bake").click()
    live_page.wait_for(f'!document.querySelector("{row} .take-baked").hidden', timeout=10)
    with page.expect_download() as got:
        page.locator(f"{row} .take-baked").click()
    got.value.save_as(tmp_path / "rider.csv")
    take = read_frames(str(tmp_path / "take.csv"))
    baked = read_frames(str(tmp_path / "rider.csv"))
    assert list(baked.names) == list(RIDER_NAMES) and len(baked) == len(take) > 10
    # The bake is the rules over the take's horse (the take is in metres, like the service).
    model = RiderModel(scale=DEFAULT_SCALE)
    horse = np.column_stack([take.column(n) for n in HORSE_NAMES])
    want = np.array([model.evaluate(list(r)) for r in horse])
    assert np.allclose(baked.values, want, atol=1e-6)


def test_without_webgl2_the_page_says_so_and_still_works(browser: Any, server: Server) -> None:
    page = browser.new_page(viewport={"width": 1024, "height": 700})
    try:
        page.add_init_script(
            """const real = HTMLCanvasElement.prototype.getContext;
            HTMLCanvasElement.prototype.getContext = function (kind, ...rest) {
                return kind === "webgl2" ? null : real.call(this, kind, ...rest);
            };"""
        )
        page.goto(server.url + "/")
        page.wait_for_function("() => window.riderlive && riderlive.frames > 10 && riderlive.view3d === false")
        assert page.locator("#no3d").is_visible()
        assert "WebGL 2" in page.locator("#no3d").inner_text()
        assert page.evaluate("() => riderlive.history('cog.ty', 5).length") > 10
        assert page.evaluate("() => riderlive.errors") == []
    finally:
        page.close()


def test_the_primitive_renderer_stays_available(browser: Any, server: Server) -> None:
    p = open_page(browser, server.url, "/?render=sticks")
    try:
        p.wait_for("riderlive.frames > 10 && riderlive.fps > 0")
        assert p.state("riderlive.render") == "sticks"
        assert p.errors == [] and p.state("riderlive.errors") == []
    finally:
        p.page.close()
