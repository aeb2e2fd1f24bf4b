"""The take browser's REST: download, bake, parameter groups (riderlive/service/takes_api.py)."""

from __future__ import annotations

import io
import json
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from riderlive.channels import HORSE_NAMES, RIDER_NAMES
from riderlive.framefile import read_frames
from riderlive.horse import DEFAULT_SCALE, ProceduralHorse
from riderlive.rules import RiderModel
from riderlive.rules.params import RuleParams, load_preset
from tests.service.live_server import LiveServer

TAKE = "browser-take"


@pytest.fixture(scope="module")
def take(server: LiveServer) -> np.ndarray:
    """A canter take in metres (sidecar length_scale 25) in the server's takes directory; its horse rows."""
    horse = ProceduralHorse("canter", 6.0, seed=3)
    rows = np.array([horse.sample(k / 120) for k in range(240)])
    folder = server.workdir / "takes"
    folder.mkdir(exist_ok=True)
    lines = [",".join(["t", *HORSE_NAMES])]
    lines += [",".join([repr(k / 120), *(repr(float(v)) for v in row)]) for k, row in enumerate(rows)]
    (folder / f"{TAKE}.csv").write_text("\n".join(lines) + "\n")
    (folder / f"{TAKE}.json").write_text(json.dumps({"name": TAKE, "length_scale": DEFAULT_SCALE}))
    return rows


def rider_of(rows: np.ndarray, params: RuleParams) -> np.ndarray:
    model = RiderModel(params=params, scale=DEFAULT_SCALE)
    return np.array([model.evaluate(list(row)) for row in rows])


def test_download_is_the_take_as_recorded(server: LiveServer, take: np.ndarray) -> None:
    response = server.get(f"/api/takes/{TAKE}/file")
    assert response.status_code == 200
    assert response.content == (server.workdir / "takes" / f"{TAKE}.csv").read_bytes()
    assert TAKE in response.headers["content-disposition"]


def test_bake_runs_the_rules_as_set_now_over_the_takes_horse(server: LiveServer, take: np.ndarray) -> None:
    key, changed = "head.lift_gain", 7.5
    before = server.get("/api/params").json()[key]
    assert server.request("PATCH", "/api/params", json={key: changed}).status_code == 200
    try:
        response = server.request("POST", f"/api/takes/{TAKE}/bake", json={})
        assert response.status_code == 200, response.text
        answer = response.json()["bake"]
    finally:
        server.request("PATCH", "/api/params", json={key: before})
    assert answer["rows"] == len(take) and answer["channels"] == list(RIDER_NAMES)
    assert answer["length_scale"] == DEFAULT_SCALE
    baked = server.get(answer["download"])
    assert baked.status_code == 200
    table = read_frames_from(baked.content)
    # The service's rules with the changed weight, recomputed here from the same horse.
    want = rider_of(take, load_preset("kuhnel2003").with_values({key: changed}))
    assert table.values.shape == want.shape
    assert np.allclose(table.values, want, rtol=1e-9, atol=1e-9)
    # A named preset bakes with that preset instead, in Parquet when asked.
    answer = server.request("POST", f"/api/takes/{TAKE}/bake", json={"preset": "child", "format": "parquet"}).json()
    assert answer["bake"]["preset"] == "child"
    table = read_frames_from(server.get(f"/api/takes/{TAKE}/baked").content, ".parquet")
    assert np.allclose(table.values, rider_of(take, load_preset("child")), rtol=1e-9, atol=1e-9)


def read_frames_from(data: bytes, suffix: str = ".csv") -> Any:
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"baked{suffix}"
        path.write_bytes(data)
        return read_frames(str(path))


@pytest.mark.parametrize(
    ("method", "path", "status"),
    [
        ("GET", "/api/takes/no-such-take/file", 404),
        ("POST", "/api/takes/no-such-take/bake", 404),
        ("GET", "/api/takes/never-baked/baked", 404),
        ("GET", "/api/takes/a.b/file", 422),
        ("GET", "/api/takes/..%2Fservice.toml/file", 404),  # no route: never a file outside the takes
        ("POST", "/api/takes/-x/bake", 422),
    ],
)
def test_unknown_or_bad_names_are_refused(server: LiveServer, method: str, path: str, status: int) -> None:
    response = server.request(method, path)
    assert response.status_code == status, response.text
    assert "detail" in response.json()


def test_the_take_being_recorded_is_not_baked_or_downloaded(server: LiveServer) -> None:
    assert server.request("POST", "/api/record/start", json={"name": "busy-take"}).status_code == 200
    try:
        for method, path in (("POST", "/api/takes/busy-take/bake"), ("GET", "/api/takes/busy-take/file")):
            assert server.request(method, path).status_code == 409
    finally:
        server.request("POST", "/api/record/stop")


def test_overwriting_the_take_being_recorded_is_a_409_and_the_service_keeps_answering(server: LiveServer) -> None:
    body = {"name": "dup-take", "overwrite": True}
    assert server.request("POST", "/api/record/start", json=body).status_code == 200
    try:
        again = server.request("POST", "/api/record/start", json=body)  # froze the web process before
        assert again.status_code == 409 and "being recorded" in again.text
        assert server.get("/api/state").json()["recording"]["name"] == "dup-take"
    finally:
        assert server.request("POST", "/api/record/stop").status_code == 200


def test_parameter_groups_cover_every_parameter_once_in_preset_order(server: LiveServer) -> None:
    groups = server.get("/api/params/groups").json()["groups"]
    params = server.get("/api/params").json()
    keys = [k for g in groups for k in g["keys"]]
    assert sorted(keys) == sorted(params) and len(keys) == len(set(keys))
    by_group = {g["group"]: g["title"] for g in groups}
    assert by_group["lower_back"].startswith("Eq. 1-3")
    assert by_group["head"].startswith("Eq. 10-11")
    assert all(k.startswith(f"{g['group']}.") for g in groups for k in g["keys"])


BODY = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=20),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner, max_size=3),
    max_leaves=6,
)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    body=st.one_of(
        BODY,
        st.fixed_dictionaries(
            {},
            optional={
                "preset": st.sampled_from(["child", "kuhnel2003", "nope", "../x", "", "a" * 65, None, 3]),
                "format": st.sampled_from(["csv", "parquet", "jsonl", "CSV", None, 1]),
                "extra": st.just(1),
            },
        ),
    )
)
def test_bake_bodies_are_checked_strictly(server: LiveServer, take: np.ndarray, body: Any) -> None:
    """Any JSON body: 200 only for a valid one, else a 4xx with a JSON detail; never a 500."""
    response = server.request(
        "POST", f"/api/takes/{TAKE}/bake", content=json.dumps(body), headers={"content-type": "application/json"}
    )
    valid = (
        isinstance(body, dict)
        and set(body) <= {"preset", "format"}
        and body.get("preset", None) in (None, "child", "kuhnel2003", "nope")
        and body.get("format", "csv") in ("csv", "parquet")
    ) or body is None
    if valid and not (isinstance(body, dict) and body.get("preset") == "nope"):
        assert response.status_code == 200, (body, response.text)
    else:
        assert response.status_code in (404, 422), (body, response.text)
        assert "detail" in response.json()


def test_download_survives_a_parquet_only_take(server: LiveServer, take: np.ndarray) -> None:
    """A take kept only as Parquet downloads as that file."""
    from riderlive.framefile import FrameTable, write_frames

    folder = server.workdir / "takes"
    table = FrameTable(tuple(HORSE_NAMES), np.asfortranarray(take), np.arange(len(take)) / 120)
    write_frames(str(folder / "pq-only.parquet"), table)
    response = server.get("/api/takes/pq-only/file")
    assert response.status_code == 200 and response.content == (folder / "pq-only.parquet").read_bytes()
    assert io.BytesIO(response.content).read(4) == b"PAR1"
