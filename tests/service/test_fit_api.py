"""Fit a preset on the page's REST (riderlive/service/fit_api.py) against the real server.

A reference rider baked from a known preset (english) over a procedural horse take is
uploaded; the fit (in its child process) recovers english's numbers; the preset it writes
loads through ``PUT /api/preset`` and ``/api/state`` shows it. Then the bad input.
"""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from riderlive.channels import HORSE_NAMES, RIDER_NAMES
from riderlive.horse import DEFAULT_SCALE, ProceduralHorse
from riderlive.rules import RiderModel
from riderlive.rules.params import load_preset
from tests.service.live_server import HTTP, LiveServer

TAKE = "fit-take"
TRUE = "english"
RATE = 120.0


def horse_rows(gait: str, seconds: float, seed: int) -> np.ndarray:
    horse = ProceduralHorse(gait, {"trot": 3.5, "canter": 6.0}[gait], seed=seed)
    return np.array([horse.sample(k / RATE) for k in range(int(seconds * RATE))])


def csv_text(names: list[str], rows: np.ndarray) -> str:
    lines = [",".join(["t", *names])]
    lines += [",".join([repr(k / RATE), *(repr(float(v)) for v in row)]) for k, row in enumerate(rows)]
    return "\n".join(lines) + "\n"


def write_take(server: LiveServer, name: str, rows: np.ndarray, rider: np.ndarray | None = None) -> None:
    """A take in metres (sidecar length_scale 25): the horse, and the rider beside it when given."""
    folder = server.workdir / "takes"
    folder.mkdir(exist_ok=True)
    names = list(HORSE_NAMES) + (list(RIDER_NAMES) if rider is not None else [])
    values = rows if rider is None else np.hstack([rows, rider])
    (folder / f"{name}.csv").write_text(csv_text(names, values))
    (folder / f"{name}.json").write_text(json.dumps({"name": name, "length_scale": DEFAULT_SCALE}))


def bake(rows: np.ndarray, preset: str) -> np.ndarray:
    model = RiderModel(params=load_preset(preset), scale=DEFAULT_SCALE)
    return np.array([model.evaluate(list(row)) for row in rows])


@pytest.fixture(scope="module")
def take(server: LiveServer) -> np.ndarray:
    rows = horse_rows("canter", 8.0, seed=5)
    write_take(server, TAKE, rows)
    return rows


def upload(server: LiveServer, name: str, data: bytes, **query: Any) -> httpx.Response:
    return server.request(
        "PUT", f"/api/takes/{name}/reference", params=query, content=data, headers={"content-type": "text/csv"}
    )


def fit(server: LiveServer, path: str, body: dict[str, Any]) -> httpx.Response:
    """A fit takes seconds (a child process, niced, on a busy host): a long client timeout."""
    return HTTP.post(server.base + path, json=body, timeout=180.0)


def recovered(report: dict[str, Any], truth: str) -> list[str]:
    """The identified numbers of ``report`` that are not ``truth``'s within 1 % (1e-3 where it is 0)."""
    want = load_preset(truth).flat()
    off = []
    for p in report["parameters"]:
        if p["identified"]:
            true = want[p["name"]]
            tolerance = 1e-3 if true == 0 else 0.01 * abs(true)
            if abs(p["value"] - true) > tolerance:
                off.append(f"{p['name']}: {p['value']} != {true}")
    return off


def test_an_uploaded_reference_rider_fits_its_preset_which_then_applies(server: LiveServer, take: np.ndarray) -> None:
    listed = {t["name"]: t for t in server.get("/api/takes").json()["takes"]}
    assert listed[TAKE]["reference"] is None, "a horse-only take has nothing to fit against"
    rider = bake(take, TRUE)
    reply = upload(server, TAKE, csv_text(list(RIDER_NAMES), rider).encode(), format="csv")
    assert reply.status_code == 200, reply.text
    assert reply.json()["reference"]["source"] == "uploaded"
    assert reply.json()["reference"]["channels"] == len(RIDER_NAMES)
    listed = {t["name"]: t for t in server.get("/api/takes").json()["takes"]}
    assert listed[TAKE]["reference"] == "uploaded" and "references" not in listed

    response = fit(server, f"/api/takes/{TAKE}/fit", {"preset": "fitted-english", "start": "kuhnel2003"})
    assert response.status_code == 200, response.text
    report = response.json()["fit"]
    assert report["preset"] == "fitted-english" and report["reference"] == "uploaded"
    assert report["start"] == "kuhnel2003"
    assert abs(report["takes"][0]["offset_s"]) < 1e-6, "the same clock"
    identified = [p for p in report["parameters"] if p["identified"]]
    assert len(identified) >= 40, "a canter identifies the weights and offsets of Eq. 1-18"
    assert recovered(report, TRUE) == []
    for channel in report["takes"][0]["channels"]:
        assert channel["rms"] is not None and channel["rms"] < 1e-4, channel
        assert channel["r"] is None or channel["r"] > 0.9999, channel
    assert (server.workdir / "presets" / "fitted-english.toml").is_file()
    assert "fitted-english" in server.get("/api/presets").json()["presets"]

    before = server.get("/api/state").json()["preset"]
    try:
        assert server.request("PUT", "/api/preset", json={"name": "fitted-english"}).status_code == 200
        assert server.get("/api/state").json()["preset"] == "fitted-english"
        params = server.get("/api/params").json()
        for p in identified:
            assert params[p["name"]] == pytest.approx(p["value"], rel=1e-12, abs=1e-12), p["name"]
    finally:
        server.request("PUT", "/api/preset", json={"name": before})

    # The same name again: 409 unless asked to overwrite.
    again = server.request("POST", f"/api/takes/{TAKE}/fit", json={"preset": "fitted-english"})
    assert again.status_code == 409 and "exists" in again.text


def test_a_recorded_take_fits_against_its_own_rider(server: LiveServer) -> None:
    rows = horse_rows("trot", 6.0, seed=8)
    write_take(server, "recorded-child", rows, bake(rows, "child"))
    listed = {t["name"]: t for t in server.get("/api/takes").json()["takes"]}
    assert listed["recorded-child"]["reference"] == "recorded"
    assert server.get("/api/takes/recorded-child/reference").json()["reference"]["source"] == "recorded"
    body = {"preset": "fitted-child", "start": "kuhnel2003"}
    response = fit(server, "/api/takes/recorded-child/fit", body)
    assert response.status_code == 200, response.text
    report = response.json()["fit"]
    assert report["reference"] == "recorded"
    assert sum(p["identified"] for p in report["parameters"]) >= 40
    assert recovered(report, "child") == []


def test_bad_input_is_refused_with_a_reason_and_counted(server: LiveServer, take: np.ndarray) -> None:
    write_take(server, "horse-only", take[:240])
    before = server.metric("riderlive_rest_rejected_total", 'status="404"')
    for method, path, body, status, reason in (
        ("POST", "/api/takes/no-such-take/fit", {"preset": "x1"}, 404, "no such take"),
        ("POST", "/api/takes/horse-only/fit", {"preset": "x1"}, 404, "no reference rider"),
        ("POST", "/api/takes/horse-only/fit", {"preset": "x1", "reference": "uploaded"}, 404, "no uploaded"),
        ("GET", "/api/takes/horse-only/reference", None, 404, "no reference rider"),
        ("POST", f"/api/takes/{TAKE}/fit", {"preset": "x1", "start": "nope"}, 404, "no preset"),
        ("POST", f"/api/takes/{TAKE}/fit", {"preset": "kuhnel2003"}, 409, "shipped"),
        ("POST", f"/api/takes/{TAKE}/fit", {"preset": "../x"}, 422, "preset"),
        ("POST", f"/api/takes/{TAKE}/fit", {"preset": "x1", "reference": "mocap"}, 422, "reference"),
        ("POST", f"/api/takes/{TAKE}/fit", {"preset": "x1", "extra": 1}, 422, "extra"),
        ("POST", f"/api/takes/{TAKE}/fit", {}, 422, "preset"),
    ):
        kwargs: dict[str, Any] = {} if body is None else {"json": body}
        response = server.request(method, path, **kwargs)
        assert response.status_code == status, (path, body, response.text)
        assert reason in response.text, (path, body, response.text)
    assert server.metric("riderlive_rest_rejected_total", 'status="404"') >= before + 5

    # Malformed reference files: 422 saying why, nothing kept (the good reference stays).
    good = server.get(f"/api/takes/{TAKE}/reference").json()
    for data, query, reason in (
        (b"t,head.rz\n0,1\n1,nan\n", {"format": "csv"}, "not a rider take"),
        (b"t,not.a_channel\n0,1\n1,2\n", {"format": "csv"}, "unknown channel"),
        (b"HIERARCHY\nROOT x\n{", {"format": "bvh"}, "not a rider take"),
        (b"PAR1garbage", {"format": "parquet"}, "not a rider take"),
        (b"", {"format": "csv"}, "empty"),
        (b"t,head.rz\n0,1\n", {"format": "xlsx"}, "format"),
        (b"t,head.rz\n0,1\n", {"format": "csv", "bonemap": "mixamo"}, "BVH"),
        (b"t,head.rz\n0,1\n", {"format": "csv", "length_scale": "-1"}, "length_scale"),
        (b"t,head.rz\n0,1\n", {"format": "bvh", "bonemap": "../x"}, "bonemap"),
    ):
        response = upload(server, TAKE, data, **query)
        assert response.status_code == 422, (data, query, response.text)
        assert reason in response.text, (data, query, response.text)
        assert str(server.workdir) not in response.text, "names, never the server's paths"
    assert server.get(f"/api/takes/{TAKE}/reference").json() == good
    leftovers = [p.name for p in (server.workdir / "takes" / "references").iterdir() if p.name.startswith(".")]
    assert leftovers == []
    assert upload(server, "no-such-take", b"t,head.rz\n0,1\n1,2\n", format="csv").status_code == 404


def test_a_take_the_fit_cannot_use_is_a_422_with_the_reason(server: LiveServer, take: np.ndarray) -> None:
    """A reference rider a minute after the horse: no overlap in time (found in the child process)."""
    write_take(server, "late-rider", take[:480])
    rider = bake(take[:480], TRUE)
    lines = [",".join(["t", *RIDER_NAMES])]
    lines += [",".join([repr(60.0 + k / RATE), *(repr(float(v)) for v in row)]) for k, row in enumerate(rider)]
    assert upload(server, "late-rider", ("\n".join(lines) + "\n").encode(), format="csv").status_code == 200
    response = fit(server, "/api/takes/late-rider/fit", {"preset": "late1"})
    assert response.status_code == 422 and "cannot be fitted" in response.text, response.text
    assert str(server.workdir) not in response.text
    assert not (server.workdir / "presets" / "late1.toml").exists(), "no preset from takes that cannot be used"


def test_one_fit_at_a_time(server: LiveServer) -> None:
    rows = horse_rows("canter", 4.0, seed=11)
    write_take(server, "long-take", rows, bake(rows, TRUE))
    first: dict[str, httpx.Response] = {}

    def run() -> None:
        body = {"preset": "long1", "start": "kuhnel2003"}
        first["reply"] = fit(server, "/api/takes/long-take/fit", body)

    thread = threading.Thread(target=run)
    thread.start()
    refused = None
    # A second fit that could not start anyway (no such starting preset: 404) is refused
    # with 409 while the first runs: the service keeps answering meanwhile.
    while thread.is_alive() and refused is None:
        reply = server.request("POST", "/api/takes/long-take/fit", json={"preset": "long2", "start": "nope"})
        assert reply.status_code in (404, 409), reply.text
        refused = reply if reply.status_code == 409 else None
    thread.join()
    assert refused is not None and "a fit is running" in refused.text, "refused while the first ran"
    assert first["reply"].status_code == 200, first["reply"].text
    assert recovered(first["reply"].json()["fit"], TRUE) == []


def test_the_schema_probe_covers_the_fit_routes_with_a_real_take(server: LiveServer, take: np.ndarray) -> None:
    """test_rest_safety's OpenAPI walk, on the new routes with a take that exists (not ``{name}``):
    a broken body is a 4xx JSON error, never a 500, and starts no fit."""
    from tests.service.test_rest_safety import endpoints, prober

    write_take(server, "probe-take", take[:240])  # no reference rider: a valid body would be a 404
    doc = server.get("/openapi.json").json()
    routes = [r for r in endpoints(doc) if r[1] in ("/api/takes/{name}/fit", "/api/takes/{name}/reference")]
    assert {(m, p) for m, p, _ in routes} == {
        ("POST", "/api/takes/{name}/fit"),
        ("PUT", "/api/takes/{name}/reference"),
        ("GET", "/api/takes/{name}/reference"),
    }
    seen: dict[str, set[int]] = {}
    with httpx.Client(base_url=server.base, timeout=10.0) as client:
        for method, path, schema in routes:
            prober(client, method, path.replace("{name}", "probe-take"), schema, doc, seen)()
    assert all(400 <= code < 500 for codes in seen.values() for code in codes), seen
    assert not list((server.workdir / "presets").glob("*probe*"))


def test_a_fit_over_its_time_is_killed_and_writes_nothing(tmp_path: Path) -> None:
    """``takes.fit_timeout``: the child process is killed (no preset, no process left) and the reason given."""
    import asyncio
    from concurrent.futures import ThreadPoolExecutor

    from riderlive.rules.params import PRESET_DIR
    from riderlive.service.fit_api import _run
    from riderlive.service.fit_worker import FitJob

    rows = horse_rows("canter", 4.0, seed=2)
    take = tmp_path / "t.csv"
    take.write_text(csv_text(list(HORSE_NAMES) + list(RIDER_NAMES), np.hstack([rows, bake(rows, TRUE)])))
    (tmp_path / "t.json").write_text(json.dumps({"length_scale": DEFAULT_SCALE}))
    output = tmp_path / "out.toml"
    job = FitJob(horse=str(take), start=str(PRESET_DIR / "kuhnel2003.toml"), output=str(output), name="out")
    with ThreadPoolExecutor(1) as pool:  # its own event loop (another test's may be running in this thread)
        code, out, reason = pool.submit(lambda: asyncio.run(_run(job, 0.05))).result()  # far under its imports
    assert (code, out) == (-1, b"") and "takes.fit_timeout" in reason
    assert not output.exists() and not list(tmp_path.glob(".out.toml.*")), "nothing written, nothing partial"


def test_the_worker_refuses_a_bad_job_with_status_2(capsys: pytest.CaptureFixture[str]) -> None:
    from riderlive.service.fit_worker import main

    assert main(["fit_worker", '{"horse": "x.csv", "unknown": 1}'], nice=0) == 2
    job = '{"horse": "/nonexistent/x.csv", "start": "kuhnel2003", "output": "o", "name": "o"}'
    assert main(["fit_worker", job], nice=0) == 2
    assert "nonexistent" in capsys.readouterr().err
