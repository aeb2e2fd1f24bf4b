"""REST against the real server: bad bodies get a 4xx with a JSON error, never a 500 or a file's contents.

The property test walks ``/openapi.json``: for every endpoint with a body it builds a
valid body from the schema and breaks one thing in it (a wrong type, NaN, an infinity,
1e400, a number out of bounds, a name that is a path, bytes that are not JSON...);
every endpoint without a body gets junk bodies and must not fail either.
"""

from __future__ import annotations

import json
from typing import Any

import httpx
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from riderlive.framefile import read_frames
from riderlive.horse import GAIT_TABLE, MOVES
from tests.service.live_server import LiveServer
from tests.waiting import wait_until

SECRET = "hunter2-do-not-echo"


@pytest.fixture(scope="module")
def server_rest(server: LiveServer) -> LiveServer:
    """The session server (its ``tick.preset_dirs`` is ``presets`` in its working directory)."""
    (server.workdir / "app.toml").write_text(f'[lower_back]\npivot_weight = "{SECRET}"\n')
    presets = server.workdir / "presets"
    presets.mkdir(exist_ok=True)
    (presets / "latin1.toml").write_bytes(b'description = "caf\xe9"\n')
    (presets / "broken.toml").write_text(f'[head]\noffset = "{SECRET}"\n')
    (presets / "folder.toml").mkdir(exist_ok=True)
    (presets / "mine.toml").write_text('description = "a deployment preset"\n[head]\noffset = 7.0\n')
    return server


def is_json_error(response: httpx.Response) -> bool:
    try:
        body = response.json()
    except ValueError:
        return False
    return isinstance(body, dict) and "detail" in body


def test_presets_are_names_from_the_preset_directories_only(server_rest: LiveServer) -> None:
    for name, status in (
        (".", 422),
        ("..", 422),
        ("../app", 422),
        ("app", 404),  # a TOML file in the working directory is not a preset
        ("/etc/passwd", 422),
        ("a.b", 422),
        ("folder", 404),  # a directory named like a preset
        ("latin1", 422),  # not UTF-8
        ("broken", 422),  # invalid values
    ):
        response = server_rest.request("PUT", "/api/preset", json={"name": name})
        assert response.status_code == status, (name, response.text)
        assert is_json_error(response) and SECRET not in response.text and "caf" not in response.text
    assert server_rest.request("PUT", "/api/preset", json={"name": "mine"}).json() == {"current": "mine"}
    assert server_rest.get("/api/params").json()["head.offset"] == 7.0
    listed = server_rest.get("/api/presets").json()["presets"]
    assert {"mine", "kuhnel2003", "child"} <= set(listed) and "folder" not in listed
    server_rest.request("PUT", "/api/preset", json={"name": "kuhnel2003"})


@pytest.mark.parametrize("literal", ["NaN", "Infinity", "-Infinity", "1e400"])
def test_non_finite_numbers_are_422(server_rest: LiveServer, literal: str) -> None:
    for method, path, template in (
        ("PATCH", "/api/params", '{"head.offset": %s}'),
        ("PUT", "/api/animator", '{"offsets": {"head.rz": %s}}'),
        ("PUT", "/api/source", '{"kind": "procedural", "speed": %s}'),
    ):
        response = server_rest.request(
            method, path, content=template % literal, headers={"content-type": "application/json"}
        )
        assert response.status_code == 422, (path, literal, response.text)
        assert is_json_error(response)


def test_parameters_that_would_make_the_rider_non_finite_are_refused(server_rest: LiveServer) -> None:
    before = server_rest.get("/api/params").json()
    response = server_rest.request("PATCH", "/api/params", json={"lower_back.pivot_weight": 1e307})
    assert response.status_code == 422 and "non-finite" in response.json()["detail"]
    assert server_rest.get("/api/params").json() == before, "nothing changed"
    response = server_rest.request("PUT", "/api/animator", json={"gains": {"head.rz": 1e308}})
    assert response.status_code == 422


def test_a_body_over_the_limit_is_413(server_rest: LiveServer) -> None:
    response = server_rest.request("PATCH", "/api/params", content=b"{" + b" " * 70000 + b"}")
    assert response.status_code == 413 and is_json_error(response)


def test_takes_are_never_overwritten_and_a_refused_start_changes_nothing(server_rest: LiveServer) -> None:
    takes = server_rest.workdir / "takes"
    assert server_rest.request("POST", "/api/record/start", json={"name": "keep"}).status_code == 200
    rows = lambda: server_rest.get("/api/state").json()["recording"]["rows"]  # noqa: E731
    wait_until(lambda: rows() > 40, 10.0, rows)
    first = server_rest.request("POST", "/api/record/stop").json()["take"]
    assert first["rows"] > 30
    assert server_rest.request("POST", "/api/record/start", json={"name": "other"}).status_code == 200
    for body, status in (({"name": "keep"}, 409), ({"name": "../bad"}, 422), ({"name": "a.b"}, 422)):
        response = server_rest.request("POST", "/api/record/start", json=body)
        assert response.status_code == status, (body, response.text)
        assert server_rest.get("/api/state").json()["recording"]["name"] == "other", "still recording"
    assert len(read_frames(str(takes / "keep.csv"))) == first["rows"], "the existing take is untouched"
    # overwrite: the old take stays whole until the new one is complete
    assert server_rest.request("POST", "/api/record/start", json={"name": "keep", "overwrite": True}).status_code == 200
    wait_until(lambda: rows() > first["rows"] + 20, 10.0, rows)  # the new take is longer, flushed more than once
    assert len(read_frames(str(takes / "keep.csv"))) == first["rows"]
    second = server_rest.request("POST", "/api/record/stop").json()["take"]
    assert len(read_frames(str(takes / "keep.csv"))) == second["rows"] != first["rows"]
    meta = json.loads((takes / "keep.json").read_text())
    assert meta["rows"] == second["rows"] and meta["complete"] is True
    listed = {t["name"]: t for t in server_rest.get("/api/takes").json()["takes"]}
    assert listed["keep"]["complete"] is True and "other" in listed
    assert server_rest.request("PUT", "/api/source", json={"kind": "replay", "take": "nope"}).status_code == 404


# -- the property test over the OpenAPI document ---------------------------------------

PATH_LIKE = ["", ".", "..", "../app", "/etc/passwd", "a/b", "a.b", "x" * 65, "-x", " a", "a\x00", "é"]
NOT_NUMBERS = [None, "abc", [], {}, [1.0], {"a": 1}]
NON_FINITE = ["NaN", "Infinity", "-Infinity", "1e400", "-1e999"]


def deref(schema: dict[str, Any], doc: dict[str, Any]) -> dict[str, Any]:
    if "$ref" in schema:
        name = schema["$ref"].rsplit("/", 1)[1]
        return deref(doc["components"]["schemas"][name], doc)
    return schema


def variants(schema: dict[str, Any], doc: dict[str, Any]) -> list[dict[str, Any]]:
    """The object schemas a body may be (oneOf/anyOf alternatives, null left out)."""
    schema = deref(schema, doc)
    for key in ("oneOf", "anyOf"):
        if key in schema:
            return [v for option in schema[key] for v in variants(option, doc) if v.get("type") != "null"]
    return [schema]


def valid_value(schema: dict[str, Any], doc: dict[str, Any]) -> Any:
    schema = deref(schema, doc)
    if "const" in schema:
        return schema["const"]
    if "anyOf" in schema:
        return None if any(s.get("type") == "null" for s in schema["anyOf"]) else valid_value(schema["anyOf"][0], doc)
    kind = schema.get("type")
    if kind == "string":
        return "kuhnel2003" if "pattern" in schema else "x"
    if kind in ("number", "integer"):
        return schema.get("minimum", 0)
    if kind == "boolean":
        return False
    if kind == "object":
        required = schema.get("required", [])
        return {k: valid_value(v, doc) for k, v in schema.get("properties", {}).items() if k in required}
    return None


def bad_values(schema: dict[str, Any], doc: dict[str, Any]) -> st.SearchStrategy[Any]:
    """Values that break ``schema`` (raw JSON text for non-finite numbers, marked by a tuple)."""
    schema = deref(schema, doc)
    options = [o for o in schema.get("anyOf", [schema]) if o.get("type") != "null"]
    kinds = {deref(o, doc).get("type") for o in options} | ({"const"} if "const" in schema else set())
    out: list[st.SearchStrategy[Any]] = []
    if "const" in schema:
        out.append(st.sampled_from(["", "dance", 1, None, [schema["const"]]]))
    if "string" in kinds:
        patterned = any("pattern" in deref(o, doc) for o in options)
        out.append(st.sampled_from([1, 2.5, [], {}] + (PATH_LIKE if patterned else ["x" * 65])))
        if not patterned:
            out.append(st.sampled_from([1, [], {}]))
    if kinds & {"number", "integer"}:
        out.append(st.sampled_from(NOT_NUMBERS[1:]))
        out.append(st.sampled_from(NON_FINITE).map(lambda literal: ("raw", literal)))
        for option in (deref(o, doc) for o in options):
            if "maximum" in option:
                out.append(st.floats(min_value=option["maximum"] + 1e-6, max_value=1e300))
            if "minimum" in option:
                out.append(st.floats(min_value=-1e300, max_value=option["minimum"] - 1e-6))
    if "boolean" in kinds:
        out.append(st.sampled_from(["maybe", 2, [], {}]))
    if "object" in kinds:
        values = schema.get("additionalProperties")
        out.append(st.sampled_from(["x", 1, []]))
        if isinstance(values, dict):
            out.append(bad_values(values, doc).map(lambda v: {"head.rz": v}))
    return st.one_of(out) if out else st.just([])


def encode(body: Any) -> bytes:
    """JSON with ``("raw", literal)`` placeholders spliced in as bare literals (NaN, 1e400)."""
    raws: list[str] = []

    def mark(value: Any) -> Any:
        if isinstance(value, tuple) and len(value) == 2 and value[0] == "raw":
            raws.append(value[1])
            return f"@@RAW{len(raws) - 1}@@"
        if isinstance(value, dict):
            return {k: mark(v) for k, v in value.items()}
        if isinstance(value, list):
            return [mark(v) for v in value]
        return value

    text = json.dumps(mark(body))
    for i, literal in enumerate(raws):
        text = text.replace(f'"@@RAW{i}@@"', literal)
    return text.encode()


def bad_bodies(schema: dict[str, Any], doc: dict[str, Any]) -> st.SearchStrategy[bytes]:
    """Bodies that break ``schema`` in one place, or are not JSON objects at all."""
    junk = st.one_of(
        st.binary(max_size=64).filter(lambda b: b.strip() not in (b"", b"null", b"{}")),
        st.sampled_from([b"[]", b'"x"', b"1", b"true", b"{", b'{"a": }', b"\xff\xfe{}"]),
    )
    broken = []
    for variant in variants(schema, doc):
        base = valid_value(variant, doc)
        for key, prop in variant.get("properties", {}).items():
            broken.append(bad_values(prop, doc).map(lambda v, base=base, key=key: encode({**base, key: v})))
        if variant.get("additionalProperties"):
            broken.append(bad_values(variant["additionalProperties"], doc).map(lambda v: encode({"head.offset": v})))
            broken.append(st.just(encode({"no.such_key": 1.0})))
    return st.one_of(junk, *broken)


def endpoints(doc: dict[str, Any]) -> list[tuple[str, str, dict[str, Any] | None]]:
    out = []
    for path, operations in doc["paths"].items():
        for method, operation in operations.items():
            body = operation.get("requestBody", {}).get("content", {}).get("application/json", {}).get("schema")
            out.append((method.upper(), path, body))
    return out


def prober(client: httpx.Client, method: str, path: str, schema: Any, doc: dict[str, Any], seen: dict) -> Any:
    @settings(max_examples=15, deadline=None, suppress_health_check=list(HealthCheck), database=None)
    @given(body=bad_bodies(schema, doc) if schema else st.binary(max_size=64))
    def check(body: bytes) -> None:
        response = client.request(method, path, content=body, headers={"content-type": "application/json"})
        seen.setdefault(f"{method} {path}", set()).add(response.status_code)
        assert response.status_code < 500, (method, path, body, response.text)
        if schema is not None:
            assert 400 <= response.status_code < 500, (method, path, body, response.text)
            assert is_json_error(response), (method, path, body, response.text)
            assert "NaN" not in response.text and "Infinity" not in response.text

    return check


def test_every_endpoint_answers_bad_bodies_with_a_4xx_json_error(server_rest: LiveServer) -> None:
    doc = server_rest.get("/openapi.json").json()
    listed = endpoints(doc)
    assert len(listed) >= 15
    client = httpx.Client(base_url=server_rest.base, timeout=10.0)
    seen: dict[str, set[int]] = {}
    try:
        for method, path, schema in listed:
            prober(client, method, path, schema, doc, seen)()
    finally:
        client.post("/api/reset")
        client.put("/api/source", json={"kind": "live"})
        client.close()
    assert set(seen) == {f"{m} {p}" for m, p, _ in listed}, "every endpoint was probed"
    with_body = {f"{m} {p}" for m, p, schema in listed if schema}
    assert all(all(400 <= code < 500 for code in seen[key]) for key in with_body)


def test_a_speed_must_suit_its_gait_and_a_refusal_changes_nothing(server_rest: LiveServer) -> None:
    """The tick would refuse them (and a restarted tick could not start on them): 422 here."""
    before = server_rest.get("/api/state").json()["source"]
    horse = server_rest.get("/api/horse").json()
    assert horse["moves"] == list(MOVES)
    table = {g.value: {"speed": list(spec.speed), "default": spec.default_speed} for g, spec in GAIT_TABLE.items()}
    assert horse["gaits"] == table
    for body, reason in (
        ({"kind": "procedural", "gait": "walk", "speed": 4.0}, "1.4-1.8"),
        ({"kind": "procedural", "gait": "gallop", "speed": 8.9}, "9.0-17.0"),
        ({"kind": "procedural", "speed": 4.0}, "needs its gait"),
    ):
        reply = server_rest.request("PUT", "/api/source", json=body)
        assert reply.status_code == 422 and reason in reply.text, (body, reply.text)
    assert server_rest.get("/api/state").json()["source"] == before
