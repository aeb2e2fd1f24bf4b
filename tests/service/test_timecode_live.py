"""Timecode through the real service at 29.97 DF: producer ``tc``, bad ones, take stamps,
``/api/takes?order=timecode`` and replay "from TC" (docs/timecode.md)."""

from __future__ import annotations

import itertools
import json
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from websockets.sync.client import connect

from riderlive import timecode as tc
from riderlive.channels import HORSE_NAMES
from riderlive.horse import DEFAULT_SCALE, ProceduralHorse
from riderlive.timecode import RATES, Rate
from tests.service.conftest import BASE_CONFIG
from tests.service.live_server import LiveServer
from tests.service.producers import Follower
from tests.waiting import wait_until

RATE = Rate.FPS_29_97_DF
FPS = float(RATES[RATE].fps)
START = tc.parse("10:00:00;00", RATE)


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    live = LiveServer(BASE_CONFIG + '\n[timecode]\nrate = "29.97df"\n', tmp_path_factory.mktemp("tc"))
    yield live
    live.stop()


class TimecodeProducer:
    """A /ws/horse producer sending frame k at t = k / 120 s labelled START + floor(t * fps)."""

    def __init__(self, server: LiveServer) -> None:
        self.ws = connect(server.ws + "/ws/horse").__enter__()
        self.welcome = json.loads(self.ws.recv(timeout=5))
        self.k = 0

    def send(self, label: str | None = None, extra: dict[str, Any] | None = None) -> float:
        t = self.k / 120
        self.k += 1
        frame = {"t": t, "values": {"root.tz": 0.1}, "tc": label or tc.format_frames(START + int(t * FPS), RATE)}
        self.ws.send(json.dumps({**frame, **(extra or {})}))
        return t

    def stream(self, seconds: float) -> None:
        t0, k0 = time.perf_counter(), self.k
        for n in range(1, int(seconds * 120) + 1):
            self.send()
            time.sleep(max(0.0, t0 + n / 120 - time.perf_counter()))  # the producer's own pacing
        assert self.k == k0 + int(seconds * 120)

    def messages(self, timeout: float = 0.3) -> list[dict[str, Any]]:
        out = []
        try:
            while True:
                out.append(json.loads(self.ws.recv(timeout=timeout)))
        except TimeoutError:
            return out


def _metric(server: LiveServer, reason: str) -> float:
    return server.metric("riderlive_timecode_errors_total", f'reason="{reason}"')


def test_producer_timecode_stamps_the_take(server: LiveServer) -> None:
    producer = TimecodeProducer(server)
    follower = Follower(server.ws)
    sender = threading.Thread(target=producer.stream, args=(3.0,), daemon=True)
    try:
        sender.start()
        follower.wait_for(lambda f: f["driver"] == "input", timeout=5.0)  # after source.resume_after
        assert server.request("POST", "/api/record/start", json={"name": "tc-producer"}).status_code == 200
        first_t = producer.k / 120
        rows = lambda: server.get("/api/state").json()["recording"]["rows"]  # noqa: E731
        wait_until(lambda: rows() >= 30, 10.0, rows)  # a few rows into the take
        assert server.request("POST", "/api/record/stop").status_code == 200
        sender.join()
    finally:
        producer.ws.close()
        follower.close()
    meta = json.loads((server.workdir / "takes" / "tc-producer.json").read_text())
    assert meta["timecode_source"] == "producer" and meta["timecode_rate"] == "29.97df"
    frames = tc.parse(meta["timecode"], RATE)
    # the first row shows a frame the producer sent before or while recording started
    assert START + int((first_t - 0.25) * FPS) <= frames <= START + int((first_t + 0.25) * FPS) + 1
    listed = {t["name"]: t for t in server.get("/api/takes").json()["takes"]}
    assert listed["tc-producer"]["timecode"] == meta["timecode"]


def test_bad_timecodes_are_answered_counted_and_the_frames_still_drive(server: LiveServer) -> None:
    cases = [
        ("10:00:00:00", None, "timecode_rate"),  # ':' is a non-drop label: another rate
        ("10:00:00;00", "25", "timecode_rate"),
        ("10:00:00;45", None, "timecode_rate"),
        ("10:01:00;00", None, "timecode_malformed"),  # a dropped label
        ("ten o'clock", None, "timecode_malformed"),
    ]
    for label, rate, reason in cases:
        before = _metric(server, reason)
        producer = TimecodeProducer(server)
        try:
            producer.send(label, {"tc_rate": rate} if rate else None)
            answers = producer.messages()
        finally:
            producer.ws.close()
        errors = [m for m in answers if m.get("type") == "error"]
        assert [e["reason"] for e in errors] == [reason], answers
        assert label[:8] in errors[0]["message"] or "tc_rate" in errors[0]["message"]
        assert any(m.get("type") == "control" and m["driving"] for m in answers), "the frame still drives"
        assert _metric(server, reason) == before + 1


def test_a_jump_is_told_and_counted(server: LiveServer) -> None:
    before = _metric(server, "timecode_jump")
    producer = TimecodeProducer(server)
    try:
        for _ in range(5):
            producer.send()
        producer.send(tc.format_frames(START + 3000, RATE))
        jumps = [m for m in producer.messages() if m.get("type") == "timecode"]
    finally:
        producer.ws.close()
    assert len(jumps) == 1 and jumps[0]["reason"] == "jump"
    assert jumps[0]["frames"] == 3000  # predicted from the previous label (START + 0) and 1/120 s: START + 0
    assert _metric(server, "timecode_jump") == before + 1


def _write_take(folder: Path, name: str, label: str | None, seconds: float = 3.0) -> None:
    horse = ProceduralHorse("canter", 6.0, seed=5)
    rows = [horse.sample(k / 120) for k in range(int(seconds * 120))]
    lines = [",".join(["t", *HORSE_NAMES])]
    lines += [",".join([repr(k / 120), *(repr(float(v)) for v in row)]) for k, row in enumerate(rows)]
    folder.mkdir(exist_ok=True)
    (folder / f"{name}.csv").write_text("\n".join(lines) + "\n")
    meta: dict[str, Any] = {"name": name, "length_scale": DEFAULT_SCALE, "tick_rate": 120.0, "complete": True}
    if label is not None:
        meta |= {"timecode": label, "timecode_rate": RATE.value, "timecode_source": "producer"}
    (folder / f"{name}.json").write_text(json.dumps(meta))


def test_takes_are_listed_by_timecode(server: LiveServer) -> None:
    folder = server.workdir / "takes"
    _write_take(folder, "tc-late", "23:00:00;00", 0.1)
    _write_take(folder, "tc-early", "00:00:01;00", 0.1)
    _write_take(folder, "tc-none", None, 0.1)
    names = [t["name"] for t in server.get("/api/takes", params={"order": "timecode"}).json()["takes"]]
    ours = [n for n in names if n in ("tc-late", "tc-early", "tc-none")]
    assert ours == ["tc-early", "tc-late", "tc-none"]
    assert server.get("/api/takes", params={"order": "size"}).status_code == 422


def test_replay_from_tc_starts_within_one_tick(server: LiveServer) -> None:
    _write_take(server.workdir / "takes", "tc-replay", "10:00:00;00")
    follower = Follower(server.ws)
    try:
        for from_tc, offset in (("10:00:01;00", 30 / FPS), ("10:00:02;15", 75 / FPS)):
            body = {"kind": "replay", "take": "tc-replay", "from_tc": from_tc}
            mark = len(follower.frames)  # the replay's first frames may arrive before the PUT's reply
            response = server.request("PUT", "/api/source", json=body)
            assert response.status_code == 200, response.text
            assert response.json()["from_tc"] == from_tc
            first = follower.wait_for(lambda f: f["driver"] == "input" and f["source_t"] > 0.5, 10.0, mark)
            # the take's rows are 1/120 s apart: the replay starts on the row nearest the label,
            # shown at the first tick that ran after it came in; a tick starved past deadlines
            # (skipped, counted) shows it that much later (18.5 ms at load 12)
            before = follower.frames[max(0, follower.frames.index(first) - 1)]
            skipped = max(0.0, first["t"] - before["t"] - 1 / 200)
            assert abs(first["source_t"] - offset) <= 1 / 120 + skipped, (first["source_t"], offset, skipped)
            server.request("PUT", "/api/source", json={"kind": "live"})
            # the replay's end in the stream (its producer gone, the input no longer drives):
            # the next replay's first frame comes after this one's last
            follower.wait_for(lambda f: f["driver"] != "input", timeout=5.0)
    finally:
        follower.close()
    for bad, status in (("09:00:00;00", 400), ("10:00:01:00", 400), ("10:00", 422)):
        body = {"kind": "replay", "take": "tc-replay", "from_tc": bad}
        assert server.request("PUT", "/api/source", json=body).status_code == status


def test_state_shows_the_timecode(server: LiveServer) -> None:
    state = server.get("/api/state").json()["timecode"]
    assert state["rate"] == "29.97df" and state["source"] in ("host", "stage")
    tc.parse(state["tc"], RATE)


def test_ws_rider_frames_carry_the_timecode_when_asked(server: LiveServer) -> None:
    with connect(server.ws + "/ws/rider") as ws:
        hello = json.loads(ws.recv(timeout=5))
        assert hello["timecode"]["rate"] == "29.97df"
        ws.send(json.dumps({"type": "subscribe", "timecode": True}))
        frames = []
        while len(frames) < 5:
            message = json.loads(ws.recv(timeout=5))
            if message["type"] == "subscribed":
                assert message["timecode"] is True
            if message["type"] == "frame" and "tc" in message:
                frames.append(message)
        labels = [tc.parse(f["tc"], RATE) for f in frames]
        # 200 Hz ticks: 0 or 1 label between two that ran one after the other; a starved tick's
        # skipped deadlines (load 12) are as many labels as their time (engine time t, s)
        for (a, b), (fa, fb) in zip(itertools.pairwise(labels), itertools.pairwise(frames), strict=True):
            assert abs(tc.frames_between(b, a, RATE) - (fb["t"] - fa["t"]) * FPS) <= 1, (a, b, fa["t"], fb["t"])
        ws.send(json.dumps({"type": "subscribe", "timecode": True, "encoding": "binary"}))
        from riderlive.service.rider_frames import decode_binary_frame

        while True:
            message = ws.recv(timeout=5)
            if isinstance(message, bytes):
                frame = decode_binary_frame(message)
                assert abs(tc.frames_between(frame["tc_frames"], labels[-1], RATE)) < 30 * 5
                break
        ws.send(json.dumps({"type": "subscribe", "timecode": "yes"}))
        while True:
            message = ws.recv(timeout=5)
            if isinstance(message, str) and json.loads(message)["type"] == "error":
                assert "timecode" in json.loads(message)["message"]
                break
