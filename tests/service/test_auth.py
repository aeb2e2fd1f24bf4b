"""Tokens for ingest and control when the service is not loopback-only."""

from __future__ import annotations

import json
import re
import tomllib
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi import FastAPI
from fastapi.routing import APIRoute
from fastapi.testclient import TestClient
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from riderlive.cli import main
from riderlive.service import auth
from riderlive.service.app import create_app
from riderlive.service.config import ServiceConfig
from tests.service.live_server import LiveServer
from tests.waiting import wait_until

TOKEN = "s3cret-Token_42"
CONFIG = f"""
[tick]
rate = 100.0
realtime_priority = false
spare = false  # not about failover: one process less per start
[security]
require_token = true    # as if bound to a public address (tests stay on loopback)
token = "{TOKEN}"
"""


@pytest.fixture(scope="module")
def guarded(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    live = LiveServer(CONFIG, tmp_path_factory.mktemp("auth"), host="127.0.0.2")
    yield live
    live.stop()


def closed_code(ws) -> int:
    with pytest.raises(ConnectionClosed) as closed:
        while True:
            ws.recv(timeout=7)
    assert closed.value.rcvd is not None
    return closed.value.rcvd.code


def test_ingest_without_or_with_a_wrong_token_is_refused(guarded: LiveServer) -> None:
    for first in ({"type": "hello"}, {"type": "hello", "token": "wrong-token-123"}):
        with connect(guarded.ws + "/ws/horse") as ws:
            ws.send(json.dumps(first))
            error = json.loads(ws.recv(timeout=7))
            assert error == {"type": "error", "reason": "unauthorized", "message": "token required"}
            assert closed_code(ws) == 4401


def test_token_as_subprotocol_like_a_browser(guarded: LiveServer) -> None:
    with connect(guarded.ws + "/ws/horse", subprotocols=["riderlive.v1", f"riderlive.token.{TOKEN}"]) as ws:
        assert ws.subprotocol == "riderlive.v1", "the token is never echoed back"
        assert json.loads(ws.recv(timeout=5))["type"] == "welcome"
        ws.send(json.dumps({"t": 0.0, "values": {"rearPivot.rz": 1.0}}))
        assert json.loads(ws.recv(timeout=5)) == {"type": "control", "driving": True}


def test_token_in_the_first_message(guarded: LiveServer) -> None:
    with connect(guarded.ws + "/ws/horse") as ws:
        ws.send(json.dumps({"type": "hello", "token": TOKEN, "name": "godot"}))
        assert json.loads(ws.recv(timeout=5))["type"] == "welcome"


def test_control_needs_the_bearer_token_publish_stays_open(guarded: LiveServer) -> None:
    assert guarded.request("PUT", "/api/source", json={"kind": "live"}).status_code == 401
    ok = guarded.request("PUT", "/api/source", json={"kind": "live"}, headers={"Authorization": f"Bearer {TOKEN}"})
    assert ok.status_code == 200
    assert guarded.get("/api/state").status_code == 200
    with connect(guarded.ws + "/ws/rider") as ws:
        assert json.loads(ws.recv(timeout=5))["type"] == "hello"


def test_the_token_never_reaches_the_log(guarded: LiveServer) -> None:
    with connect(guarded.ws + "/ws/horse", subprotocols=["riderlive.v1", f"riderlive.token.{TOKEN}"]) as ws:
        ws.recv(timeout=5)
    guarded.request("GET", "/api/state", headers={"Authorization": f"Bearer {TOKEN}"})
    # the log is read on a thread as the server writes it: a connection after the two with the
    # token, its line awaited, is the mark that everything they logged has been read (a fresh
    # clone once read the log before the first connection's line)
    with connect(guarded.ws + "/ws/rider") as ws:
        ws.recv(timeout=5)
    wait_until(lambda: "/ws/rider" in "".join(guarded.log), 5.0, lambda: "".join(guarded.log)[-600:])
    log = "".join(guarded.log)
    assert "/ws/horse" in log and TOKEN not in log


def test_publish_may_require_the_token(tmp_path: Path) -> None:
    live = LiveServer(CONFIG + "publish_requires_token = true\n", tmp_path, token=TOKEN)
    try:
        with connect(live.ws + "/ws/rider") as ws:
            ws.send(json.dumps({"type": "auth", "token": "nope-nope-nope"}))
            assert json.loads(ws.recv(timeout=7))["reason"] == "unauthorized"
        with connect(live.ws + "/ws/rider", subprotocols=["riderlive.v1", f"riderlive.token.{TOKEN}"]) as ws:
            assert json.loads(ws.recv(timeout=5))["type"] == "hello"
        assert live.get("/api/state").status_code == 401
    finally:
        live.stop()


def test_a_public_address_without_a_token_does_not_start(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ValueError, match=r"security\.token"):
        ServiceConfig.model_validate({"server": {"host": "0.0.0.0"}})
    assert not ServiceConfig.model_validate({"server": {"host": "127.0.0.2"}}).token_required
    assert ServiceConfig.model_validate({"server": {"host": "10.1.2.3"}, "security": {"token": TOKEN}}).token_required
    assert main(["serve", "--host", "0.0.0.0"]) == 2
    assert "security.token" in capsys.readouterr().err


def test_an_estop_needs_no_token_reset_and_arm_do(guarded: LiveServer) -> None:
    """Decision (docs/hardware.md, "E-stop without the token"): an e-stop is never locked.
    Off loopback, without the token, REST and the websocket control channel latch it,
    counted apart; reset (which alone ends it, and never arms) needs the token."""
    bearer = {"Authorization": f"Bearer {TOKEN}"}

    def latched() -> bool:
        return bool(guarded.get("/api/devices", headers=bearer).json()["estop"])

    def by_source(source: str, authorized: str) -> float:
        return guarded.metric(
            "riderlive_estop_requests_by_source_total", f'source="{source}",authorized="{authorized}"'
        )

    assert not latched()
    answer = guarded.request("POST", "/api/estop", json={"not": "looked at"})
    assert answer.status_code == 200 and answer.json()["estop"] is True and answer.json()["authorized"] is False
    assert 0.0 <= answer.json()["latched_at"] - answer.json()["received_at"] < 0.05
    assert latched() and by_source("rest", "no") == 1
    assert guarded.request("POST", "/api/reset").status_code == 401 and latched()
    assert guarded.request("POST", "/api/reset", headers=bearer).status_code == 200 and not latched()
    with connect(guarded.ws + "/ws/rider") as ws:

        def ack() -> dict:
            for _ in range(1000):  # frames and status come between
                message = json.loads(ws.recv(timeout=10))
                if message.get("type") == "estop":
                    return dict(message)
            raise AssertionError("no estop acknowledgement")

        ws.send(json.dumps({"type": "estop", "id": 7}))
        first = ack()
        assert first["id"] == 7 and first["authorized"] is False
        assert latched() and by_source("websocket", "no") == 1
        ws.send(json.dumps({"type": "auth", "token": TOKEN}))
        ws.send(json.dumps({"type": "estop", "id": 8}))
        second = ack()
        assert second["id"] == 8 and second["authorized"] is True
        assert by_source("websocket", "yes") == 1
    assert guarded.request("POST", "/api/estop", headers=bearer).json()["authorized"] is True
    assert by_source("rest", "yes") == 1
    assert guarded.request("POST", "/api/arm", json={"device": "x"}).status_code == 401
    assert guarded.request("POST", "/api/reset").status_code == 401 and latched()
    assert guarded.request("POST", "/api/reset", headers=bearer).status_code == 200 and not latched()
    assert guarded.get("/healthz").status_code == 200 and guarded.get("/readyz").status_code == 200


# --- every REST write: 401 before its body is read (auth.WriteGuard) ---

BAD_BODIES = (b"{", b'{"device": 5, "nope": [1, 2', b'{"device": "no such device!", "intensity": "x"}', b"", b"[" * 64)
NO_TOKEN = (
    {},
    {"Authorization": "Bearer wrong-token-123"},
    {"Authorization": TOKEN},
    {"Authorization": f"Basic {TOKEN}"},
)
NEVER_LOCKED = {("POST", "/api/estop")}  # stops without the token: test_an_estop_needs_no_token_reset_and_arm_do
DEVICE_WRITES = {
    ("POST", "/api/arm"),
    ("POST", "/api/disarm"),
    ("POST", "/api/reset"),
    ("POST", "/api/reload"),
    ("PATCH", "/api/platform"),
}


def config_of(text: str) -> ServiceConfig:
    return ServiceConfig.model_validate(tomllib.loads(text))


def write_routes(app: FastAPI) -> list[tuple[str, str]]:
    """(method, path) of every REST write in the app's route table; path parameters filled in."""
    out = []
    for route in app.routes:
        if isinstance(route, APIRoute):
            path = re.sub(r"\{[^}]+\}", "take1", route.path)
            out += [(method, path) for method in sorted(route.methods & auth.WRITE_METHODS)]
    return out


def test_every_write_route_answers_401_before_its_body(guarded: LiveServer) -> None:
    """Off loopback (require_token), each write of the route table with each bad body and no
    valid token: 401 with the refusal, never 422 (the body is not even read)."""
    every = write_routes(create_app(config_of(CONFIG)))
    assert set(every) >= DEVICE_WRITES | NEVER_LOCKED and len(every) >= len(DEVICE_WRITES) + 8, every
    routes = [route for route in every if route not in NEVER_LOCKED]
    before = {
        a: guarded.metric("riderlive_device_refusals_total", f'action="{a}",reason="unauthorized"')
        for a in ("arm", "tune")
    }
    for method, path in routes:
        for body in BAD_BODIES:
            for headers in NO_TOKEN:
                answer = guarded.request(
                    method, path, content=body, headers={"Content-Type": "application/json", **headers}
                )
                assert answer.status_code == 401, (method, path, body, headers, answer.text)
                assert answer.json()["detail"]["refusal"] == "unauthorized"
                assert answer.headers["www-authenticate"] == "Bearer"
    tries = len(BAD_BODIES) * len(NO_TOKEN)
    for action, was in before.items():  # each refusal counted under its action
        now = guarded.metric("riderlive_device_refusals_total", f'action="{action}",reason="unauthorized"')
        assert now - was == tries, action
    # with the token the same bad body is read and refused for what it is (not 401)
    auth_header = {"Authorization": f"Bearer {TOKEN}", "Content-Type": "application/json"}
    for method, path in (
        ("POST", "/api/arm"),
        ("PATCH", "/api/platform"),
        ("PUT", "/api/source"),
        ("PATCH", "/api/params"),
    ):
        assert guarded.request(method, path, content=b"{", headers=auth_header).status_code == 422, (method, path)


def test_the_write_rules_on_loopback_and_for_a_route_added_later() -> None:
    """Loopback with a token configured: the arming writes (arm, reset, reload, platform tune)
    need it, the others read their body (a bad one: 422); a route added after the app was
    built is a write like any other."""
    loopback = create_app(config_of(f'[security]\ntoken = "{TOKEN}"\n'))
    client = TestClient(loopback)  # no lifespan: the routes answer before any tick is needed
    arming = {(m, p) for (m, p), rule in auth.WRITE_RULES.items() if rule.rule is auth.Rule.ARMING}
    assert arming == {("POST", "/api/arm"), ("POST", "/api/reset"), ("POST", "/api/reload"), ("PATCH", "/api/platform")}
    acting = {("POST", "/api/estop"), ("POST", "/api/record/stop")}  # no body: with none needed they would act
    for method, path in sorted(set(write_routes(loopback)) - acting):
        answer = client.request(method, path, content=b"{", headers={"Content-Type": "application/json"})
        assert answer.status_code == (401 if (method, path) in arming else 422), (method, path, answer.text)
    public = create_app(config_of(CONFIG))

    @public.delete("/api/something-new")
    async def something_new() -> dict[str, bool]:
        return {"deleted": True}

    public.router.routes.insert(0, public.router.routes.pop())  # before the page's mount at /
    assert TestClient(public).delete("/api/something-new").status_code == 401
    ok = TestClient(public).delete("/api/something-new", headers={"Authorization": f"Bearer {TOKEN}"})
    assert ok.status_code == 200 and ok.json() == {"deleted": True}


def test_write_rule_table() -> None:
    assert auth.write_rule("GET", "/api/arm") is None and auth.write_rule("options", "/api/arm") is None
    assert auth.write_rule("post", "/api/arm/") == auth.WriteRule(auth.Rule.ARMING, "arm")
    assert auth.write_rule("POST", "/api/estop") == auth.WriteRule(auth.Rule.NEVER_LOCKED, "estop")
    assert auth.write_rule("PUT", "/api/anything") is auth.DEFAULT_WRITE
