"""``riderlive serve --nats`` against a real nats-server: frames, status, horse input and its
arbitration against /ws/horse, control with the service's token rules, bad messages counted,
a rig name that is taken, a broker that refuses us, takes in JetStream."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import msgpack
import orjson
import pytest
from websockets.sync.client import connect as ws_connect

from riderlive.bus.broker import Broker
from riderlive.bus.config import NatsSection
from riderlive.bus.nats import Credentials, connect
from riderlive.bus.stage import discover, preflight
from riderlive.bus.subjects import Kind, Stage
from riderlive.bus.takes import export, list_takes, record, replay
from riderlive.bus.transport import Refused
from riderlive.channels import HORSE_NAMES, RIDER_NAMES, SADDLE_NAMES
from riderlive.service.rider_frames import decode_binary_frame
from riderlive.takes.replay import load_replay
from tests.bus.harness import AUTH, RIG_TICK, TOKEN, NatsProbe, start_rig, wait_for
from tests.bus.harness import TOKEN_CONFIG as CONFIG
from tests.service.live_server import ROOT, LiveServer
from tests.service.producers import Producer
from tests.waiting import Pacer, wait_until

STAGE = Stage("A")
RIG = STAGE.rig("r1")


@pytest.fixture(scope="module")
def rig(broker: Broker, tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    live = start_rig(tmp_path_factory.mktemp("r1"), broker.url, "A", "r1", CONFIG, token=TOKEN)
    yield live
    live.stop()
    assert "Traceback" not in "".join(live.log), "".join(live.log)


@pytest.fixture
def probe(broker: Broker) -> Iterator[NatsProbe]:
    p = NatsProbe(broker.url)
    yield p
    p.close()


def state(live: LiveServer) -> dict:
    return live.get("/api/state", headers=AUTH).json()


def _metric(live: LiveServer, reason: str) -> float:
    for line in live.get("/metrics", headers=AUTH).text.splitlines():
        if line.startswith(f'riderlive_bad_frames_total{{reason="{reason}"}} '):
            return float(line.rsplit(" ", 1)[1])
    return 0.0


def test_every_tick_reaches_nats_identical_to_ws_rider_saddle_pose_included(rig: LiveServer, probe: NatsProbe) -> None:
    frames = probe.collect(RIG.subject(Kind.FRAME))
    ws_frames: dict[int, dict] = {}
    with ws_connect(rig.ws + "/ws/rider", subprotocols=["riderlive.v1"]) as ws:  # type: ignore[list-item]
        subscribe = {"type": "subscribe", "encoding": "binary", "horse_channels": list(HORSE_NAMES), "saddle": True}
        ws.send(json.dumps(subscribe))
        deadline = time.perf_counter() + 1.0
        while time.perf_counter() < deadline:
            message = ws.recv(timeout=5)
            if isinstance(message, bytes):
                frame = decode_binary_frame(message)
                ws_frames[frame["seq"]] = frame
    wait_for(lambda: len(frames) > 50, say=lambda: len(frames))
    nats = {f["seq"]: f for f in (decode_binary_frame(m.data) for _, m in list(frames))}
    seqs = sorted(nats)
    missing = (seqs[-1] - seqs[0] + 1) - len(seqs)
    if missing:  # only ticks the rig counted as dropped (a starved web process) or skipped may be missing
        status = orjson.loads(probe.request(RIG.subject(Kind.CONTROL), orjson.dumps({"action": "state"})))
        counts = status["counts"]  # frames_skipped: ticks the tick skipped when late, or the web process never read
        assert missing <= counts.get("frames_dropped", 0) + counts.get("frames_skipped", 0), (missing, status)
    common = sorted(set(nats) & set(ws_frames))
    assert len(common) > 20
    for seq in common:  # the same record, the same codec: bit-identical values
        assert nats[seq]["values"] == ws_frames[seq]["values"]
        assert nats[seq]["horse"] == ws_frames[seq]["horse"]
        assert nats[seq]["saddle"] == ws_frames[seq]["saddle"] and nats[seq]["estimate"] == ws_frames[seq]["estimate"]
        assert len(nats[seq]["values"]) == len(RIDER_NAMES) and len(nats[seq]["horse"]) == len(HORSE_NAMES)
        assert len(nats[seq]["saddle"]) == len(SADDLE_NAMES) and nats[seq]["estimate"] is None  # a horse drives


def test_discover_and_status_say_who_and_how_fast(rig: LiveServer, probe: NatsProbe) -> None:
    statuses = probe.collect(RIG.subject(Kind.STATUS))
    rigs = probe.call(discover(probe.transport, STAGE, 0.3))
    assert [r["rig"] for r in rigs] == ["r1"]
    assert rigs[0]["session"] == state(rig)["session"] and rigs[0]["tick_up"] is True
    wait_for(lambda: any(orjson.loads(m.data)["rates"] for _, m in statuses), timeout=3.0)
    rates = next(orjson.loads(m.data)["rates"] for _, m in reversed(statuses) if orjson.loads(m.data)["rates"])
    assert 50.0 < rates["ticks_hz"] < 130.0 and 50.0 < rates["frames_out_hz"] < 130.0  # tick.rate = 100


def horse(value: float) -> dict:
    return {"values": {"root.ty": value}}


def test_nats_and_websocket_producers_share_one_arbiter(rig: LiveServer, probe: NatsProbe) -> None:
    subject = RIG.horse("p1")
    replies = probe.collect(inbox := probe.transport.new_inbox())
    stop = threading.Event()

    def feed() -> None:
        probe.call(probe.transport.publish(subject, orjson.dumps({"type": "hello", "token": TOKEN}), inbox))
        n, pacer = 0, Pacer(0.01)
        while not stop.is_set():
            n += 1
            body = {"t": time.time(), **horse(0.25)}
            probe.call(probe.transport.publish(subject, msgpack.packb(body), inbox))
            pacer.wait()

    thread = threading.Thread(target=feed, daemon=True)
    thread.start()
    try:

        def active() -> str | None:
            arb = state(rig)["arbitration"]
            return next((p["name"] for p in arb["producers"] if p["id"] == arb["active"]), None)

        wait_for(lambda: active() == "nats:p1", say=lambda: state(rig)["arbitration"])
        wait_for(lambda: any(orjson.loads(m.data).get("driving") is True for _, m in replies))
        # a websocket producer of higher priority takes over at its next frame...
        ws = Producer(
            rig.ws,
            lambda t: {"t": t, **horse(-0.25)},
            hello={"priority": 5, "name": "ws-high"},
            subprotocols=["riderlive.v1", f"riderlive.token.{TOKEN}"],
        )
        try:
            wait_for(lambda: active() == "ws-high", say=lambda: state(rig)["arbitration"])
            wait_for(lambda: any(orjson.loads(m.data).get("driving") is False for _, m in replies))
        finally:
            ws.closed.set()
            ws.ws.close()
        # ...and the NATS producer, still sending, drives again once it has gone
        wait_for(lambda: active() == "nats:p1", say=lambda: state(rig)["arbitration"])
        wait_for(lambda: state(rig)["tick"]["driver"] == "input", say=lambda: state(rig)["tick"])
    finally:
        stop.set()
        thread.join(5)


def test_bad_messages_are_refused_answered_and_counted(rig: LiveServer, probe: NatsProbe) -> None:
    inbox = probe.transport.new_inbox()
    replies = probe.collect(inbox)
    before = {r: _metric(rig, r) for r in ("malformed", "oversize", "unknown_version", "unauthorized", "out_of_range")}
    send = lambda subject, data: probe.call(probe.transport.publish(subject, data, inbox))  # noqa: E731
    send(RIG.horse("bad1"), b"\xc1\x00 not msgpack")
    send(RIG.horse("bad1"), b"{" + b" " * 5000 + b"}")  # max_message_bytes = 4096
    send(RIG.horse("bad2"), orjson.dumps({"t": 1.0, **horse(0.1)}))  # no token in a hello first
    send(RIG.horse("bad3", version="v9"), orjson.dumps({"type": "hello", "token": TOKEN}))
    send(RIG.horse("bad4"), orjson.dumps({"type": "hello", "token": TOKEN}))
    send(RIG.horse("bad4"), orjson.dumps({"t": 1.0, **horse(1e6)}))
    errors = lambda: [orjson.loads(m.data) for _, m in list(replies) if orjson.loads(m.data).get("type") == "error"]  # noqa: E731
    wait_for(lambda: len(errors()) >= 5, say=lambda: replies)
    assert sorted(e["reason"] for e in errors()) == [
        "malformed",
        "out_of_range",
        "oversize",
        "unauthorized",
        "unknown_version",
    ]
    for reason, count in before.items():
        assert _metric(rig, reason) == count + 1, reason
    control = probe.request(RIG.subject(Kind.CONTROL, "v2"), orjson.dumps({"action": "state"}))
    assert orjson.loads(control)["refusal"] == "unknown_version"
    assert _metric(rig, "unknown_version") == before["unknown_version"] + 2
    assert state(rig)["tick_alive"]


def test_control_follows_the_rest_token_rules(rig: LiveServer, probe: NatsProbe) -> None:
    ask = lambda body: orjson.loads(probe.request(RIG.subject(Kind.CONTROL), orjson.dumps(body)))  # noqa: E731
    assert ask({"action": "disarm"})["refusal"] == "unauthorized"
    assert ask({"action": "arm", "device": "bench3"})["refusal"] == "unauthorized"
    assert ask({"action": "reset", "token": "wrong-token-1"})["refusal"] == "unauthorized"
    assert ask({"action": "fly", "token": TOKEN})["refusal"] == "unknown_action"
    assert ask({"action": "arm", "token": TOKEN})["refusal"] == "invalid"  # the device name is required
    refused = ask({"action": "arm", "device": "bench3", "token": TOKEN})
    assert refused["refusal"] == "not_ready" and "heartbeat" in refused["message"]
    assert ask({"action": "state"})["rig"] == "r1"
    # the same request answered the same way as REST (this rig has no device)
    rest = rig.request("POST", "/api/disarm", json={"device": "bench3"}, headers=AUTH)
    nats = ask({"action": "disarm", "device": "bench3", "token": TOKEN})
    assert rest.status_code == 404 and nats["ok"] is False
    assert nats["refusal"] == rest.json()["detail"]["refusal"] == "unknown_device"
    metrics = rig.get("/metrics", headers=AUTH).text
    assert 'riderlive_device_refusals_total{action="disarm",reason="unauthorized"} 1' in metrics
    assert 'riderlive_device_refusals_total{action="arm",reason="not_ready"} 1' in metrics


def test_a_taken_rig_name_is_refused(rig: LiveServer, broker: Broker, tmp_path: Path) -> None:
    (tmp_path / "svc.toml").write_text(RIG_TICK)
    command = [sys.executable, "-m", "riderlive", "serve", "--config", str(tmp_path / "svc.toml"), "--port", "0"]
    command += ["--nats", broker.url, "--stage", "A", "--rig", "r1"]
    done = subprocess.run(
        command, capture_output=True, text=True, timeout=60, cwd=tmp_path, env={"PYTHONPATH": str(ROOT)}
    )
    assert done.returncode == 2
    assert "rig name 'r1' is already in use on stage 'A'" in done.stderr


def test_a_broker_that_wants_credentials_refuses_us_without() -> None:
    import asyncio

    with Broker(user="stage", password="s3cret-pass") as guarded:
        with pytest.raises(Refused, match="refused our credentials"):
            asyncio.run(connect(guarded.url, Credentials()))
        with pytest.raises(Refused):
            asyncio.run(connect(guarded.url, Credentials(user="stage", password="wrong")))

        async def fine() -> bool:
            transport = await connect(guarded.url, Credentials(user="stage", password="s3cret-pass"))
            await transport.close()
            return True

        assert asyncio.run(fine())
        # what `serve --nats` checks before it starts (it exits 2 with this message)
        section = NatsSection(url=guarded.url, stage="A", rig="r9")
        assert "refused our credentials" in str(preflight(section))
        assert (
            preflight(NatsSection(url=guarded.url, stage="A", rig="r9", user="stage", password="s3cret-pass")) is None
        )


def test_jetstream_take_records_lists_exports_and_replays(rig: LiveServer, probe: NatsProbe, tmp_path: Path) -> None:
    t = probe.transport
    got = probe.call(record(t, STAGE, "r1", "t1", seconds=0.6, max_age=60.0, max_bytes=8 << 20))
    assert got.rig == "r1" and not got.recording and 30 <= got.frames <= 90  # ~0.6 s at 100 Hz
    assert [x.name for x in probe.call(list_takes(t, STAGE))] == ["t1"]
    # the stream captures no more once recorded: 20 more of the rig's frames (0.2 s) go by, not into it
    frames = probe.collect(RIG.subject(Kind.FRAME))
    seen = len(frames)
    wait_until(lambda: len(frames) >= seen + 20, 10.0, lambda: f"{len(frames) - seen} of 20 frames after the take")
    assert probe.call(list_takes(t, STAGE))[0].frames == got.frames
    rows = probe.call(export(t, STAGE, "t1", tmp_path / "t1.csv"))
    assert rows == got.frames
    local = load_replay(tmp_path / "t1.csv", 100.0)
    assert len(local.t) == rows
    # replay into the rig: a NATS producer like any other, counted under its name
    sent = probe.call(replay(t, STAGE, "t1", "r1", priority=3, token=TOKEN))
    assert sent == rows
    wait_for(lambda: _metric_in(rig, "nats:replay-t1") == rows, say=lambda: _metric_in(rig, "nats:replay-t1"))


def _metric_in(live: LiveServer, name: str) -> float:
    for line in live.get("/metrics", headers=AUTH).text.splitlines():
        if line.startswith(f'riderlive_frames_in_total{{producer="{name}"}} '):
            return float(line.rsplit(" ", 1)[1])
    return 0.0


def test_the_python_client_follows_a_rig_over_nats(rig: LiveServer, broker: Broker) -> None:
    import asyncio

    from riderlive.bus.subscriber import NatsRiderSubscriber

    async def take(n: int) -> list:
        subscriber = NatsRiderSubscriber(broker.url, stage="A", rig="r1")
        got = []
        async for frame in subscriber.frames():
            got.append(frame)
            if len(got) == n:
                subscriber.close()
        return got

    frames = asyncio.run(asyncio.wait_for(take(10), 20.0))
    assert [f.seq for f in frames] == sorted(f.seq for f in frames) and len({f.seq for f in frames}) == 10
    assert list(frames[0].values) == list(RIDER_NAMES) and list(frames[0].horse) == list(HORSE_NAMES)


def test_the_stage_command_lists_the_rigs(rig: LiveServer, broker: Broker) -> None:
    command = [sys.executable, "-m", "riderlive", "stage", "--nats", broker.url, "--stage", "A", "list", "--json"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=60, env={"PYTHONPATH": str(ROOT)})
    assert done.returncode == 0, done.stderr
    rigs = [json.loads(line) for line in done.stdout.splitlines()]
    assert [r["rig"] for r in rigs] == ["r1"] and rigs[0]["tick_up"] is True
    empty = subprocess.run(
        [*command[:7], "B", "list"], capture_output=True, text=True, timeout=60, env={"PYTHONPATH": str(ROOT)}
    )
    assert empty.returncode == 1 and "no rig answers on stage 'B'" in empty.stdout
