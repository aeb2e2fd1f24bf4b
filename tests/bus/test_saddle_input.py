"""Saddle input over NATS (``riderlive.v1.<stage>.<rig>.saddle.<producer>``) against a real
nats-server and a real ``riderlive serve --nats``: it drives like ``/ws/saddle`` (the
estimator locks on the gait), bad messages get ``/ws/saddle``'s error replies and counts
and change nothing, and it competes with ``/ws/horse`` producers in the one arbiter."""

from __future__ import annotations

import json
import math
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import msgpack
import numpy as np
import orjson
import pytest

from riderlive.bus.broker import Broker
from riderlive.bus.subjects import Kind, Stage
from riderlive.bus.transport import Message
from riderlive.channels import HORSE_INDEX, SADDLE_NAMES
from riderlive.horse.script import gait_script
from riderlive.saddle import Model, saddle_from_horse
from riderlive.saddle.synthetic import record
from riderlive.saddle.trial import GaitCase
from tests.bus.harness import AUTH, TOKEN, NatsProbe, start_rig, wait_for
from tests.bus.harness import TOKEN_CONFIG as CONFIG
from tests.service.live_server import LiveServer
from tests.service.producers import Follower, Producer, constant

RIG = Stage("S").rig("s1")
HOST_SILENCES = 3
"""Attempts at a case that a producer's silence (the host's, counted) may spoil."""
HELLO = orjson.dumps({"type": "hello", "token": TOKEN})


@pytest.fixture(scope="module")
def rig(broker: Broker, tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    live = start_rig(tmp_path_factory.mktemp("s1"), broker.url, "S", "s1", CONFIG, token=TOKEN)
    yield live
    live.stop()
    assert "Traceback" not in "".join(live.log), "".join(live.log)


@pytest.fixture
def probe(broker: Broker) -> Iterator[NatsProbe]:
    p = NatsProbe(broker.url)
    yield p
    p.close()


@pytest.fixture
def follower(rig: LiveServer) -> Iterator[Follower]:
    """Every frame with the horse, the saddle and the estimate (subscription acknowledged)."""
    f = Follower(rig.ws)
    f.ws.send(json.dumps({"type": "subscribe", "saddle": True}))
    f.wait_for(lambda fr: "saddle" in fr, timeout=10)
    yield f
    f.close()


def state(live: LiveServer) -> dict[str, Any]:
    return live.get("/api/state", headers=AUTH).json()


def metric(live: LiveServer, name: str, labels: str) -> float:
    """One sample of /metrics (0 when absent)."""
    for line in live.get("/metrics", headers=AUTH).text.splitlines():
        if line.startswith(f"{name}{{{labels}}} "):
            return float(line.rsplit(" ", 1)[1])
    return 0.0


def producers(live: LiveServer) -> dict[str, dict[str, Any]]:
    """/api/state's producers by name."""
    return {p["name"]: p for p in state(live)["arbitration"]["producers"]}


def active(live: LiveServer) -> dict[str, Any] | None:
    """The driving producer of /api/state (``name``, ``kind``, counts), or None."""
    arbitration = state(live)["arbitration"]
    return next((p for p in arbitration["producers"] if p["id"] == arbitration["active"]), None)


def locked_tick(live: LiveServer) -> dict[str, Any] | None:
    """/api/state's tick status once the saddle estimator has locked, else None."""
    tick: dict[str, Any] = state(live)["tick"]
    return tick if tick["saddle"] is not None and tick["saddle"]["lock"] == "locked" else None


def answers(replies: list[tuple[float, Message]]) -> list[dict[str, Any]]:
    return [orjson.loads(m.data) for _, m in list(replies)]


class NatsFeed:
    """Publishes ``(at, message)`` pairs on ``subject`` at ``at`` s after the start, from a thread,
    replies to ``inbox``; ``sending`` cleared: the due messages are skipped (silence)."""

    def __init__(self, probe: NatsProbe, subject: str, inbox: str, messages: Iterator[tuple[float, bytes]]) -> None:
        self.probe, self.subject, self.inbox = probe, subject, inbox
        self.sending = threading.Event()
        self.sending.set()
        self.stopped = threading.Event()
        self.done = threading.Event()
        self.sent = 0
        self.send(HELLO)
        self.started = time.perf_counter()
        self.thread = threading.Thread(target=self._run, args=(messages,), daemon=True)
        self.thread.start()

    def send(self, data: bytes) -> None:
        self.probe.call(self.probe.transport.publish(self.subject, data, self.inbox))

    def _run(self, messages: Iterator[tuple[float, bytes]]) -> None:
        for at, data in messages:
            if self.stopped.is_set():
                break
            time.sleep(max(0.0, self.started + at - time.perf_counter()))
            if self.sending.is_set():
                self.send(data)
                self.sent += 1
        self.done.set()

    def close(self) -> None:
        self.stopped.set()
        self.thread.join(5.0)


def trot_saddle(t: float) -> list[float]:
    """A saddle moving like a trot's (as tests/service/test_saddle_live.py): valid input."""
    w = 2.0 * math.pi * 1.4
    return [
        0.01 * math.sin(w * t),
        0.03 * math.sin(2 * w * t),
        0.01 * math.sin(w * t),
        1.0 * math.sin(w * t),
        0.5 * math.sin(w * t),
        2.0 * math.sin(2 * w * t + 1.0),
    ]


def endless(make: Callable[[float], list[float]], rate: float = 100.0) -> Iterator[tuple[float, bytes]]:
    n = 0
    while True:
        t = n / rate
        yield t, msgpack.packb({"t": t, "v": make(t)})
        n += 1


def test_bad_saddle_messages_get_the_ws_saddle_replies_counted_and_change_nothing(
    rig: LiveServer, probe: NatsProbe, follower: Follower
) -> None:
    wait_for(lambda: state(rig)["tick"]["driver"] == "procedural", say=lambda: state(rig)["tick"])
    reasons = ("malformed", "oversize", "not_finite", "out_of_range", "unknown_channel", "wrong_type")
    counted = (*reasons, "unauthorized", "unknown_version")
    before = {r: metric(rig, "riderlive_bad_frames_total", f'reason="{r}"') for r in counted}
    inbox = probe.transport.new_inbox()
    replies = probe.collect(inbox)
    started = time.perf_counter()
    send = lambda subject, data: probe.call(probe.transport.publish(subject, data, inbox))  # noqa: E731
    send(RIG.saddle("bad"), HELLO)
    for data in (
        b"\xc1\x00 not msgpack",
        b"{" + b" " * 5000 + b"}",  # max_message_bytes = 4096
        msgpack.packb({"t": 1.0, "v": [0.0, math.nan, 0.0, 0.0, 0.0, 0.0]}),
        orjson.dumps({"t": 1.1, "values": {"saddle.ty": 2.0}}),
        orjson.dumps({"t": 1.2, "values": {"rearPivot.rz": 1.0}}),  # a horse channel on the saddle subject
        orjson.dumps({"t": 1.3, "v": [0.0, 0.0]}),
    ):
        send(RIG.saddle("bad"), data)
    send(RIG.saddle("nohello"), msgpack.packb({"t": 1.0, "v": [0.0] * 6}))  # no token in a hello first
    send(RIG.saddle("bad", version="v9"), HELLO)
    errors = lambda: [a for a in answers(replies) if a.get("type") == "error"]  # noqa: E731
    wait_for(lambda: len(errors()) >= len(counted), say=lambda: answers(replies))
    by_reason = {e["reason"]: e["message"] for e in errors()}
    assert sorted(e["reason"] for e in errors()) == sorted(counted)
    assert "saddle.ty = 2.0" in by_reason["out_of_range"] and "[-1.5, 1.5]" in by_reason["out_of_range"]
    assert "unknown saddle channel 'rearPivot.rz'" in by_reason["unknown_channel"]
    welcome = next(a for a in answers(replies) if a.get("type") == "welcome")
    assert welcome["kind"] == "saddle" and [c["name"] for c in welcome["channels"]] == list(SADDLE_NAMES)
    for reason, count in before.items():
        assert metric(rig, "riderlive_bad_frames_total", f'reason="{reason}"') == count + 1, reason
    bad = producers(rig)["nats:saddle:bad"]
    assert (bad["kind"], bad["accepted"]) == ("saddle", 0)
    assert bad["rejected"] == len(reasons)
    assert metric(rig, "riderlive_frames_in_total", 'producer="nats:saddle:bad"') == 0
    # Nothing of it reached the tick: the procedural horse drove every frame, no estimate (over
    # 5 frames at least: a fast host sent and checked all of the above within 5 ticks)
    since = lambda: [f for f in follower.frames if f["at"] >= started]  # noqa: E731
    frames = wait_for(lambda: len(since()) > 5 and since())
    assert {f["driver"] for f in frames} == {"procedural"}
    assert all(f["estimate"] is None for f in frames)
    for name in ("bad", "nohello"):
        send(RIG.saddle(name), orjson.dumps({"type": "bye", "token": TOKEN}))
    wait_for(lambda: not state(rig)["arbitration"]["producers"], say=lambda: state(rig)["arbitration"])


def test_a_saddle_recording_on_nats_drives_like_ws_saddle(
    rig: LiveServer, probe: NatsProbe, follower: Follower
) -> None:
    """As tests/service/test_saddle_live.py on /ws/saddle: lock within 2 strides of the first
    sample, the estimated stride within 2 %, the published saddle the ridden horse's."""
    case = GaitCase.draw("trot", seed=3, rates=(100.0,))
    script = gait_script("trot", 4.5, case.speed, seed=case.seed + 1)
    recording = record(script, case.rate, start=case.start, seed=case.seed)
    times = recording.saddle.t
    assert times is not None
    rows = [(float(t), [float(v) for v in row]) for t, row in zip(times, recording.saddle.values, strict=True)]
    messages = ((t - rows[0][0], msgpack.packb({"t": t, "v": row})) for t, row in rows)
    inbox = probe.transport.new_inbox()
    replies = probe.collect(inbox)
    statuses = probe.collect(RIG.subject(Kind.STATUS))
    before = metric(rig, "riderlive_frames_in_total", 'producer="nats:saddle:rec"')
    mark = len(follower.frames)  # the last sample's frames are held for `hold` only: looked for from here
    feed = NatsFeed(probe, RIG.saddle("rec"), inbox, messages)
    try:
        driving = wait_for(lambda: active(rig), say=lambda: state(rig)["arbitration"])
        assert (driving["name"], driving["kind"]) == ("nats:saddle:rec", "saddle")
        locked = wait_for(lambda: locked_tick(rig), say=lambda: state(rig)["tick"])
        assert locked["driver"] == "input" and locked["saddle"]["gait"] == "trot"
        assert locked["saddle"]["stride_hz"] == pytest.approx(case.stride_hz, rel=0.02)
        assert feed.done.wait(15.0)
        follower.wait_for(lambda f: f["source_t"] >= times[-1], 10, mark)
    finally:
        feed.close()
    got = answers(replies)
    assert not [a for a in got if a.get("type") == "error"], got
    assert [a.get("type") for a in got[:2]] == ["welcome", "control"] and got[1]["driving"] is True
    assert metric(rig, "riderlive_frames_in_total", 'producer="nats:saddle:rec"') - before == len(rows)
    frames = [
        f
        for f in follower.frames
        if f["at"] >= feed.started and f["driver"] == "input" and f["estimate"] and times[0] <= f["source_t"]
    ]
    source = np.array([f["source_t"] for f in frames])
    is_locked = np.array([f["estimate"]["lock"] == "locked" and f["estimate"]["gait"] == "trot" for f in frames])
    assert is_locked[-1], frames[-1]["estimate"]
    lock_at = float(source[np.flatnonzero(~is_locked)[-1] + 1]) if not is_locked.all() else float(source[0])
    hooves_in = lock_at + Model().ease_time(case.stride_hz)
    assert (hooves_in - times[0]) * case.stride_hz <= 2.0, "lock within 2 strides of the start"
    later = [f for f in frames if f["source_t"] >= hooves_in]
    assert len(later) >= 100
    np.testing.assert_allclose([f["estimate"]["stride_hz"] for f in later], case.stride_hz, rtol=0.02)
    for f in later[::50]:
        np.testing.assert_allclose(f["saddle"], saddle_from_horse(f["horse"]), atol=1e-9)
    # The rig's status counts the saddle input's rate (100 Hz recording), no horse input.
    rates = [orjson.loads(m.data)["rates"] for _, m in list(statuses)]
    fastest = max(rates, key=lambda r: r.get("saddle_in_hz", 0.0))
    assert 50.0 < fastest["saddle_in_hz"] < 130.0 and fastest["horse_in_hz"] == 0.0, rates
    feed.send(orjson.dumps({"type": "bye"}))
    wait_for(lambda: not state(rig)["arbitration"]["producers"], say=lambda: state(rig)["arbitration"])


def test_a_nats_saddle_and_ws_horse_producers_share_one_arbiter(
    rig: LiveServer, probe: NatsProbe, follower: Follower
) -> None:
    """docs/protocol.md, "Several producers": one pool; the incumbent keeps control among
    equals, a higher priority takes over at its next frame, leaving hands back."""
    rz = HORSE_INDEX["rearPivot.rz"]
    inbox = probe.transport.new_inbox()
    replies = probe.collect(inbox)
    controls = lambda: [a["driving"] for a in answers(replies) if a.get("type") == "control"]  # noqa: E731
    token = ["riderlive.v1", f"riderlive.token.{TOKEN}"]
    feed = NatsFeed(probe, RIG.saddle("arb"), inbox, endless(trot_saddle))
    equal = high = None
    try:
        wait_for(lambda: (active(rig) or {}).get("name") == "nats:saddle:arb", say=lambda: state(rig)["arbitration"])
        wait_for(lambda: controls() == [True], say=lambda: answers(replies))
        # An equal priority on /ws/horse does not take over a live incumbent...
        for _ in range(HOST_SILENCES):
            silences = state(rig)["arbitration"]["handovers"]["silence"]
            equal = Producer(rig.ws, constant({"rearPivot.rz": 1.0}), hello={"name": "ws-equal"}, subprotocols=token)
            wait_for(lambda: (producers(rig).get("ws-equal") or {}).get("accepted", 0) >= 30)
            driving = active(rig)
            assert driving is not None
            if driving["name"] != "ws-equal":
                break
            # ...unless it fell silent for longer than input.producer_timeout (counted, with the
            # length of the silence): a busy host's (the feed's thread, the broker, the bus's
            # reader). The equal then leaves, the incumbent drives again, and the case repeats.
            arbitration = state(rig)["arbitration"]
            last = arbitration["last_handover"]
            assert arbitration["handovers"]["silence"] == silences + 1, arbitration
            assert last["to"] == "ws-equal" and last["previous"] == "nats:saddle:arb", last
            assert last["reason"] == "silence" and last["silent_for"] > 0.3, last  # harness producer_timeout
            equal.close()
            wait_for(lambda: "ws-equal" not in producers(rig) and (active(rig) or {}).get("name") == "nats:saddle:arb")
        else:
            pytest.fail(f"the NATS producer fell silent {HOST_SILENCES} times in a row")
        assert (driving["name"], driving["kind"]) == ("nats:saddle:arb", "saddle")
        assert equal.wait_driving(False) and state(rig)["tick"]["saddle"] is not None
        told = controls()  # [True], or [True, False, True, ...] after a silence
        assert told[-1] is True, told
        # ...a higher one takes over at its next frame: the NATS producer is told, the horse rides.
        high = Producer(
            rig.ws, constant({"rearPivot.rz": 2.0}), hello={"name": "ws-high", "priority": 5}, subprotocols=token
        )
        wait_for(lambda: (active(rig) or {}).get("name") == "ws-high", say=lambda: state(rig)["arbitration"])
        wait_for(lambda: controls() == [*told, False], say=lambda: answers(replies))
        frame = follower.wait_for(lambda f: f["driver"] == "input" and f["horse"][rz] == 2.0)
        assert frame["estimate"] is None
        kinds = {name: p["kind"] for name, p in producers(rig).items()}
        assert kinds == {"nats:saddle:arb": "saddle", "ws-equal": "horse", "ws-high": "horse"}
        # Both horse producers leave: the NATS saddle producer, still sending, drives again.
        equal.close()
        wait_for(lambda: "ws-equal" not in producers(rig))
        high.close()
        wait_for(lambda: controls() == [*told, False, True], say=lambda: answers(replies))
        follower.wait_for(lambda f: f["driver"] == "input" and f["estimate"] is not None, timeout=10)
        assert (active(rig) or {}).get("name") == "nats:saddle:arb"
        assert not [a for a in answers(replies) if a.get("type") == "error"]
    finally:
        for p in (equal, high):
            if p is not None:
                p.close()
        feed.close()
    feed.send(orjson.dumps({"type": "bye"}))
    wait_for(lambda: not state(rig)["arbitration"]["producers"], say=lambda: state(rig)["arbitration"])
