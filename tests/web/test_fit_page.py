"""Fit a preset on the page (web/src/fit.js) in a real Chromium against the real service.

A horse-only take has no "fit"; importing a reference rider (english, baked over the
take's horse) through "⬆ rider" gives it one; fit -> the report (per channel r and RMS,
per parameter identified or not) -> apply: the service runs the fitted preset.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from riderlive.channels import HORSE_NAMES, RIDER_NAMES
from riderlive.horse import DEFAULT_SCALE, ProceduralHorse
from riderlive.rules import RiderModel
from riderlive.rules.params import load_preset
from tests.web.conftest import STATE_FPS, PageUnderTest, Server, open_page

pytestmark = pytest.mark.browser
TAKE = "page-fit-take"
RATE = 120.0


def csv_text(names: list[str], rows: np.ndarray) -> str:
    lines = [",".join(["t", *names])]
    lines += [",".join([repr(k / RATE), *(repr(float(v)) for v in row)]) for k, row in enumerate(rows)]
    return "\n".join(lines) + "\n"


@pytest.fixture
def fit_server(server: Server) -> Iterator[Server]:
    """The shared service (its fitted presets go to ``tick.preset_dirs``), given back with the
    preset it ran before: the other modules check the rules' default rider."""
    before = server.get("/api/presets")["current"]
    try:
        yield server
    finally:
        server.request("PUT", "/api/preset", {"name": before})
        assert server.get("/api/presets")["current"] == before


def test_fit_a_preset_from_an_imported_rider_and_apply_it(browser: Any, fit_server: Server, tmp_path: Path) -> None:
    horse = ProceduralHorse("canter", 6.0, seed=4)
    rows = np.array([horse.sample(k / RATE) for k in range(int(6 * RATE))])
    takes = fit_server.workdir / "takes"
    takes.mkdir(exist_ok=True)
    (takes / f"{TAKE}.csv").write_text(csv_text(list(HORSE_NAMES), rows))
    (takes / f"{TAKE}.json").write_text(json.dumps({"name": TAKE, "length_scale": DEFAULT_SCALE}))
    model = RiderModel(params=load_preset("english"), scale=DEFAULT_SCALE)
    rider = tmp_path / "english_rider.csv"
    rider.write_text(csv_text(list(RIDER_NAMES), np.array([model.evaluate(list(r)) for r in rows])))

    p: PageUnderTest = open_page(browser, fit_server.url, max_fps=STATE_FPS)
    try:
        page = p.page
        row = f"#takes li[data-take='{TAKE}']"
        p.wait_for(f'document.querySelector("{row} .take-upload") !== null', timeout=20)
        assert page.locator(f"{row} .take-fit").count() == 0, "no reference rider: nothing to fit"
        with page.expect_file_chooser() as chooser:
            page.locator(f"{row} .take-upload").click()
        chooser.value.set_files(str(rider))
        p.wait_for(f'document.querySelector("{row} .take-fit") !== null', timeout=20)
        assert fit_server.get(f"/api/takes/{TAKE}/reference")["reference"]["source"] == "uploaded"

        page.locator(f"{row} .take-fit").click()
        assert page.locator("#fit-name").input_value() == f"{TAKE}-fit"
        page.locator("#fit-name").fill("page-english")
        page.locator("#fit-run").click()
        p.wait_for("document.getElementById('fit-apply') !== null", timeout=240)
        report = p.state("riderlive.fit.last")
        assert report["preset"] == "page-english"
        channels = page.locator("#fit-report .fit-channels tbody tr")
        assert channels.count() == len(report["takes"][0]["channels"]) == len(RIDER_NAMES)
        first = report["takes"][0]["channels"][0]
        assert channels.nth(0).locator("td").nth(0).inner_text() == first["channel"]
        assert float(channels.nth(0).locator("td").nth(1).inner_text()) == pytest.approx(first["r"], abs=1e-4)
        params = page.locator("#fit-report .fit-params tbody tr")
        assert params.count() == len(report["parameters"])
        identified = [q for q in report["parameters"] if q["identified"]]
        assert page.locator("#fit-report .fit-params tr.fit-identified").count() == len(identified) >= 40
        want = load_preset("english").flat()
        for q in identified:
            assert q["value"] == pytest.approx(want[q["name"]], rel=0.01, abs=1e-3), q["name"]
        summary = page.locator("#fit-report .fit-summary").inner_text()
        assert f"{len(identified)} of {len(report['parameters'])} numbers identified" in summary

        page.locator("#fit-apply").click()
        p.wait_for("document.getElementById('preset').value === 'page-english'", timeout=10)
        assert fit_server.get("/api/state")["preset"] == "page-english"
        assert p.errors == []
    finally:
        p.page.close()
