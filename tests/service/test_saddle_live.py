"""/ws/saddle against the real server: a saddle recording rides like the full horse, one
arbiter for both kinds, bad input counted and never a flailing rider, the saddle subscription,
takes with the saddle's channels."""

from __future__ import annotations

import json
import math
import threading
import time
from typing import Any

import msgpack
import numpy as np
import pytest
from websockets.sync.client import connect

from riderlive.channels import HORSE_INDEX, HORSE_NAMES, RIDER_INDEX, SADDLE_NAMES
from riderlive.framefile import read_frames
from riderlive.horse.model import evaluate
from riderlive.horse.script import gait_script
from riderlive.rules import RiderModel, load_preset
from riderlive.saddle import Model, saddle_from_horse, saddle_matrix
from riderlive.saddle.synthetic import IMU_STRAP, record
from riderlive.saddle.trial import COMPARED, GaitCase
from riderlive.service.rider_frames import decode_binary_frame
from tests.service.live_server import LiveServer
from tests.service.producers import Follower, Producer, Stream, constant
from tests.waiting import wait_until

MODEL = RiderModel(params=load_preset("kuhnel2003"), scale=25.0)
NEUTRAL = np.array(MODEL.evaluate([0.0] * len(HORSE_NAMES)))
ESTIMATOR = Model()


@pytest.fixture
def follower(server: LiveServer):
    """Every frame with the horse and the saddle (subscription acknowledged before the test)."""
    f = Follower(server.ws)
    f.ws.send(json.dumps({"type": "subscribe", "saddle": True}))
    f.wait_for(lambda fr: "saddle" in fr, timeout=10)
    yield f
    f.close()


def _driven(follower: Follower, since: float) -> list[dict[str, Any]]:
    """Frames received after ``since`` (perf_counter) that a saddle input drove."""
    return [f for f in follower.frames if f["at"] >= since and f["driver"] == "input" and f.get("estimate")]


def _until(condition: Any, timeout: float = 10.0) -> None:
    """Wait for ``condition()`` (a control message travels after the frames that decided it)."""
    wait_until(condition, timeout, "not within the timeout")


def _saddle_drives(frame: dict[str, Any]) -> bool:
    return frame["driver"] == "input" and frame.get("estimate") is not None


@pytest.mark.parametrize(
    ("gait", "faults", "floor"), [("trot", IMU_STRAP, 0.85), ("canter", None, 0.9)], ids=["trot-strap", "canter"]
)
def test_a_saddle_recording_rides_like_the_full_horse(
    server: LiveServer, follower: Follower, gait: str, faults, floor: float
) -> None:
    """The issue's numbers, live: lock within 2 strides of the first sample, then the rider's
    four compared channels correlate with the full horse's rider (>= 0.9 clean, >= 0.85 strap)."""
    case = GaitCase.draw(gait, seed=3, rates=(100.0,))
    script = gait_script(gait, 4.5, case.speed, seed=case.seed + 1)
    recording = record(script, case.rate, start=case.start, imperfections=faults, seed=case.seed)
    times = recording.saddle.t
    assert times is not None
    mark = len(follower.frames)  # the last sample's frames are held for `hold` only: looked for from here
    stream = Stream(server.ws, "/ws/saddle", times, recording.saddle.values, hello={"name": f"rec-{gait}"})
    try:
        assert stream.done.wait(15.0)
        follower.wait_for(lambda f: f["source_t"] >= times[-1], 10, mark)
    finally:
        stream.close()
    frames = [f for f in _driven(follower, stream.started) if times[0] <= f["source_t"] <= times[-1]]
    assert not [m for m in stream.messages if m["type"] == "error"], stream.messages
    assert stream.messages[0] == {"type": "control", "driving": True}, "driving from the first frame"
    source = np.array([f["source_t"] for f in frames])
    locked = np.array([f["estimate"]["lock"] == "locked" and f["estimate"]["gait"] == gait for f in frames])
    assert locked[-1], frames[-1]["estimate"]
    lock_at = float(source[np.flatnonzero(~locked)[-1] + 1]) if not locked.all() else float(source[0])
    hooves_in = lock_at + ESTIMATOR.ease_time(case.stride_hz)
    assert (hooves_in - times[0]) * case.stride_hz <= 2.0, "lock within 2 strides of the start"
    stride = np.array([f["estimate"]["stride_hz"] for f in frames if f["source_t"] >= hooves_in])
    np.testing.assert_allclose(stride, case.stride_hz, rtol=0.02)
    later = [f for f in frames if f["source_t"] >= hooves_in]
    # Enough ticks to judge (a follower on a loaded machine may have frames dropped: docs/protocol.md).
    assert len(later) >= 100
    truth_model = script.model()
    _, horse = evaluate(truth_model, script.start(truth_model), np.array([f["source_t"] for f in later]))
    truth = MODEL.evaluate_batch(horse)
    live = np.array([f["values"] for f in later])
    # what a failure needs to be explained (seen twice in full runs, 0.42 and 0.71 on
    # lower_back.rz for the strap, never alone): the service's messages, the frames' reading
    seen = {
        "messages": stream.messages[1:],
        "frames": len(later),
        "largest source step": float(np.diff(source).max()),
        "largest arrival gap": float(np.diff([f["at"] for f in frames]).max()),
        "r": {c: float(np.corrcoef(truth[:, RIDER_INDEX[c]], live[:, RIDER_INDEX[c]])[0, 1]) for c in COMPARED},
    }
    for channel in COMPARED:
        i = RIDER_INDEX[channel]
        assert np.corrcoef(truth[:, i], live[:, i])[0, 1] >= floor, (channel, seen)
    # The published saddle is the saddle of the horse the rules rode (the rebuilt one).
    for f in later[::50]:
        np.testing.assert_allclose(f["saddle"], saddle_from_horse(f["horse"]), atol=1e-9)


def _trot_saddle(t: float) -> dict[str, Any]:
    """A saddle moving like a trot's (vertical twice a stride of 1.4 Hz, pitch once): valid input."""
    w = 2.0 * math.pi * 1.4
    values = [0.01 * math.sin(w * t), 0.03 * math.sin(2 * w * t), 0.01 * math.sin(w * t), 1.0 * math.sin(w * t)]
    return {"t": t, "v": [*values, 0.5 * math.sin(w * t), 2.0 * math.sin(2 * w * t + 1.0)]}


def test_saddle_and_horse_producers_share_one_arbiter(server: LiveServer, follower: Follower) -> None:
    """A saddle producer competes exactly like a horse producer: priority, incumbent, silence."""
    rz = HORSE_INDEX["rearPivot.rz"]
    horse = Producer(server.ws, constant({"rearPivot.rz": 1.0}), hello={"name": "arb-horse"})
    quiet = loud = None
    try:
        follower.wait_for(lambda f: f["driver"] == "input" and f["horse"][rz] == 1.0)
        quiet = Producer(server.ws, _trot_saddle, hello={"name": "arb-saddle"}, path="/ws/saddle")
        assert quiet.welcome["kind"] == "saddle" and [c["name"] for c in quiet.welcome["channels"]] == list(
            SADDLE_NAMES
        )
        assert quiet.wait_control() is False, "an equal priority does not take over a live incumbent"
        assert not any(_saddle_drives(f) for f in follower.frames[-20:])
        loud = Producer(server.ws, _trot_saddle, hello={"name": "arb-loud", "priority": 5}, path="/ws/saddle")
        follower.wait_for(_saddle_drives, timeout=10)
        _until(lambda: loud.driving() is True and horse.driving() is False)
        # The tick writes the frame, wakes the web process, then publishes its status: a frame the
        # saddle drove can be read before the status says so (it once said None at load 10).
        _until(lambda: server.get("/api/state").json()["tick"]["saddle"] is not None)
        state = server.get("/api/state").json()
        assert set(state["tick"]["saddle"]) >= {"lock", "gait", "stride_hz", "phase", "age", "counters"}
        kinds = {p["name"]: p["kind"] for p in state["arbitration"]["producers"]}
        assert kinds == {"arb-horse": "horse", "arb-saddle": "saddle", "arb-loud": "saddle"}
        assert server.metric("riderlive_clients_connected", 'path="/ws/saddle"') == 2
        loud.close()
        # The loud one left: whichever of the equals sends next drives; silence hands over.
        frame = follower.wait_for(lambda f: f["driver"] == "input", timeout=10)
        follower.wait_for(lambda f: f["seq"] > frame["seq"] + 10, timeout=10)
        saddle_won = _saddle_drives(follower.frames[-1])
        (quiet if saddle_won else horse).sending.clear()
        follower.wait_for(lambda f: f["driver"] == "input" and _saddle_drives(f) is not saddle_won, timeout=10)
        _until(lambda: (horse if saddle_won else quiet).driving() is True)
    finally:
        for p in (horse, quiet, loud):
            if p is not None:
                p.close()


def test_bad_frames_get_the_horse_endpoints_error_replies(server: LiveServer) -> None:
    before = {r: server.metric("riderlive_bad_frames_total", f'reason="{r}"') for r in ("not_finite", "out_of_range")}
    with connect(server.ws + "/ws/saddle") as ws:
        json.loads(ws.recv(timeout=5))
        replies = []
        for message in (
            msgpack.packb({"t": 1.0, "v": [0.0, math.nan, 0.0, 0.0, 0.0, 0.0]}),
            json.dumps({"t": 1.1, "values": {"saddle.ty": 2.0}}),
            json.dumps({"t": 1.2, "values": {"rearPivot.rz": 1.0}}),
            json.dumps({"t": 1.3, "v": [0.0, 0.0]}),
        ):
            ws.send(message)
            replies.append(json.loads(ws.recv(timeout=5)))
    assert [r["reason"] for r in replies] == ["not_finite", "out_of_range", "unknown_channel", "wrong_type"]
    assert "saddle.ty = 2.0" in replies[1]["message"] and "[-1.5, 1.5]" in replies[1]["message"]
    assert "unknown saddle channel 'rearPivot.rz'" in replies[2]["message"]
    for reason, count in before.items():
        assert server.metric("riderlive_bad_frames_total", f'reason="{reason}"') == count + 1


def _run(server: LiveServer, follower: Follower, make, seconds: float, rate: float = 100.0) -> list[dict[str, Any]]:
    """Stream ``make`` to /ws/saddle for ``seconds``; the frames it drove (or that followed it,
    eased): those ticked since it connected, not those that arrived since (a loaded follower
    received the stream before's frames late, a trot's ``searching`` among a 1 Hz stream's)."""
    producer = Producer(server.ws, make, rate=rate, path="/ws/saddle")
    started = time.perf_counter()
    try:
        follower.wait_for(lambda f: f["ticked"] > started + seconds, timeout=seconds + 5)
    finally:
        producer.close()
    assert not [m for m in producer.messages if m.get("type") == "error"]
    first = follower.first_ticked_after(started)
    return [] if first is None else follower.frames[first:]


def _quiet(frames: list[dict[str, Any]]) -> float:
    """The largest distance of the rider from neutral over ``frames`` (rotations deg, lengths m)."""
    return float(max(np.abs(np.array(f["values"]) - NEUTRAL).max() for f in frames))


class OneGlitch:
    """The trotting saddle (``_trot_saddle``) and, once, on the first sample from ``at`` s of
    its clock on, a jump of a metre on every axis (within range): sent whatever the sender's
    timing (the old 8 ms window of its clock fell between two samples of a sender late by
    more than 2 ms, on a loaded host: no glitch was sent, and the count never rose)."""

    def __init__(self, at: float) -> None:
        self.at = at
        self.t = math.inf
        """The glitch sample's time (inf: not sent yet)."""
        self.sent = threading.Event()

    def __call__(self, t: float) -> dict[str, Any]:
        if t >= self.at and not self.sent.is_set():
            self.t = t
            self.sent.set()
            return {"t": t, "v": [1.0] * 6}
        return _trot_saddle(t)


def test_bad_streams_fall_back_counted_and_never_flail(server: LiveServer, follower: Follower) -> None:
    counters = ("missing", "glitches", "gaps", "stale")
    before = {c: server.metric(f"riderlive_saddle_{c}_total") for c in counters}
    rng = np.random.default_rng(5)

    # A missing axis: only the vertical and the pitch are sent; the others are missing, counted.
    frames = _run(server, follower, lambda t: {"t": t, "values": {"saddle.ty": _trot_saddle(t)["v"][1]}}, 0.6)
    assert any(_saddle_drives(f) for f in frames)
    assert server.metric("riderlive_saddle_missing_total") - before["missing"] >= 40
    # A constant stream: still, gait halt; the rider sits at neutral.
    frames = _run(server, follower, lambda t: {"t": t, "v": [0.01, 0.02, 0.0, 1.0, 2.0, 3.0]}, 1.2)
    last = [f for f in frames if _saddle_drives(f)][-1]
    assert (last["estimate"]["lock"], last["estimate"]["gait"]) == ("still", "halt")
    assert _quiet([f for f in frames if _saddle_drives(f)]) < 1e-6
    # White noise (3 cm, 3 deg): never a lock, the pose's weight stays 0: the rider sits at neutral.
    frames = _run(server, follower, lambda t: {"t": t, "v": rng.normal(0.0, [0.03] * 3 + [3.0] * 3).tolist()}, 1.5)
    driven = [f for f in frames if _saddle_drives(f)]
    assert driven and all(f["estimate"]["lock"] != "locked" for f in driven)
    assert _quiet(driven) < 1e-6
    # A jump of a metre within the range: dropped as a glitch, counted; the rider does not jump.
    glitch = OneGlitch(0.5)
    producer = Producer(server.ws, glitch, rate=100.0, path="/ws/saddle")
    started = time.perf_counter()
    try:
        assert glitch.sent.wait(10.0), "the glitch was never sent"
        follower.wait_for(lambda f: _saddle_drives(f) and f["source_t"] >= glitch.t + 0.1, timeout=10)
        _until(lambda: server.metric("riderlive_saddle_glitches_total") > before["glitches"])
    finally:
        producer.close()
    assert not [m for m in producer.messages if m.get("type") == "error"]
    frames = [f for f in follower.frames if f["at"] >= started]
    assert max(abs(f["saddle"][1]) for f in frames) < 0.1, "the published saddle never shows the jump"
    # A 1 Hz stream: every sample a gap, never a signal; the rider sits at neutral.
    frames = _run(server, follower, _trot_saddle, 3.2, rate=1.0)
    driven = [f for f in frames if _saddle_drives(f)]
    assert driven and {f["estimate"]["lock"] for f in driven} == {"no_signal"}
    assert _quiet(driven) < 1e-6
    assert server.metric("riderlive_saddle_gaps_total") - before["gaps"] >= 2
    assert server.metric("riderlive_saddle_stale_total") - before["stale"] >= 2, "it stops between samples"


def test_the_saddle_subscription_json_and_binary(server: LiveServer) -> None:
    """Whatever drives (here the procedural horse), the saddle is the saddle of the tick's horse."""
    with connect(server.ws + "/ws/rider") as ws:
        hello = json.loads(ws.recv(timeout=5))
        assert hello["hello_version"] >= 3, "version 3 fields stay in later versions"
        assert [c["name"] for c in hello["saddle"]["channels"]] == list(SADDLE_NAMES)
        assert hello["saddle"]["locks"] == ["no_signal", "still", "searching", "locked"]
        assert hello["saddle"]["point"] == {"forward": 0.6, "up": 0.15, "unit": "m"}
        ws.send(json.dumps({"type": "subscribe", "saddle": "yes"}))
        replies = [json.loads(ws.recv(timeout=5)) for _ in range(50)]
        errors = [r for r in replies if r["type"] == "error"]
        assert errors and errors[0]["reason"] == "wrong_type" and "'saddle'" in errors[0]["message"]
        assert all("saddle" not in r for r in replies if r["type"] == "frame"), "the subscription stays as it was"
        for _ in range(2000):  # a test before may have left the rider easing to neutral
            message = json.loads(ws.recv(timeout=5))
            if message.get("driver") == "procedural":
                break
        ws.send(json.dumps({"type": "subscribe", "saddle": True, "horse_channels": list(HORSE_NAMES)}))
        ack = next(m for m in (json.loads(ws.recv(timeout=5)) for _ in range(100)) if m["type"] == "subscribed")
        assert ack["saddle"] is True
        frames = [m for m in (json.loads(ws.recv(timeout=5)) for _ in range(20)) if m["type"] == "frame"]
        ws.send(json.dumps({"type": "subscribe", "encoding": "binary", "channels": ["head.rz"]}))
        binary = [decode_binary_frame(m) for m in (ws.recv(timeout=5) for _ in range(60)) if isinstance(m, bytes)]
    assert frames and binary
    for frame in frames + binary:
        assert frame["driver"] == "procedural" and frame["estimate"] is None
        np.testing.assert_allclose(frame["saddle"], saddle_from_horse(frame["horse"]), atol=1e-9)
    assert max(abs(f["saddle"][5]) for f in frames + binary) > 0.1, "the procedural horse moves the saddle"


def test_takes_record_the_saddle(server: LiveServer, follower: Follower) -> None:
    name = "saddle-take"
    producer = Producer(server.ws, _trot_saddle, rate=100.0, path="/ws/saddle")
    try:
        # The take starts once the saddle drives (on a loaded machine the producer's first
        # frames once came so late that the take held mostly the neutral horse before them).
        follower.wait_for(_saddle_drives, timeout=10)
        assert server.request("POST", "/api/record/start", json={"name": name}).json() == {"recording": name}
        started = time.perf_counter()
        # Two strides of the 1.4 Hz trot in ticks, not seconds: a starved tick skips deadlines
        # (counted; 9 rows were recorded in 1.5 s at load 14).
        follower.after(follower.wait_for(lambda f: True), 300, timeout=30.0)
        stopped = server.request("POST", "/api/record/stop").json()["take"]
    finally:
        producer.close()
    frames = [f for f in follower.frames if f["at"] >= started]
    assert stopped["rows"] > 60 and all(_saddle_drives(f) for f in frames[: len(frames) // 2])
    take = read_frames(str(server.workdir / "takes" / f"{name}.csv"))
    assert take.names[-len(SADDLE_NAMES) :] == SADDLE_NAMES
    horse = np.column_stack([take.column(n) for n in HORSE_NAMES])
    saddle = np.column_stack([take.column(n) for n in SADDLE_NAMES])
    np.testing.assert_allclose(saddle, saddle_matrix(horse), atol=1e-9)
    assert np.ptp(saddle[:, 1]) > 0.01, "the saddle moved"
