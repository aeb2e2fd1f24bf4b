"""Tokens for ingest and control when the service is not loopback-only."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from riderlive.cli import main
from riderlive.service.config import ServiceConfig
from tests.service.live_server import LiveServer

TOKEN = "s3cret-Token_42"
CONFIG = f"""
[tick]
rate = 100.0
realtime_priority = false
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
