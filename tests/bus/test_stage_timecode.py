"""The stage-wide timecode: ``riderlive stage heartbeat --tc-rate`` beats carry ``tc``; every rig on
the stage stamps its records with it (docs/timecode.md). A real nats-server, two real rigs."""

from __future__ import annotations

import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import orjson
import pytest

from riderlive import timecode as tc
from riderlive.bus.broker import Broker
from riderlive.bus.subjects import Kind, Stage
from riderlive.timecode import Rate
from tests.bus.harness import RIG_TICK, NatsProbe, start_rig, wait_for
from tests.children import popen
from tests.service.live_server import ROOT, LiveServer

STAGE = "tc"
RATE = '\n[timecode]\nrate = "29.97df"\noffset = 3600.0\n'  # the rigs' own clocks would say an hour later


@pytest.fixture(scope="module")
def rigs(broker: Broker, tmp_path_factory: pytest.TempPathFactory) -> Iterator[list[LiveServer]]:
    lives = [start_rig(tmp_path_factory.mktemp(f"r{i}"), broker.url, STAGE, f"r{i}", RIG_TICK + RATE) for i in range(2)]
    yield lives
    for live in lives:
        live.stop()


def _timecode(live: LiveServer) -> dict[str, object]:
    return dict(live.get("/api/state").json()["timecode"])


def test_every_rig_follows_the_stage_heartbeat(broker: Broker, rigs: list[LiveServer]) -> None:
    for live in rigs:
        assert _timecode(live)["source"] == "host"
    beat = popen(
        [sys.executable, "-m", "riderlive", "stage", "--nats", broker.url, "--stage", STAGE,
         "heartbeat", "--tc-rate", "29.97df", "--tc-clock", "utc"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    try:
        from riderlive.service.timecodes import host_label

        for live in rigs:
            wait_for(lambda r=live: _timecode(r)["source"] == "stage", 10.0)
            label = tc.parse(str(_timecode(live)["tc"]), Rate.FPS_29_97_DF)
            now = tc.parse(host_label(Rate.FPS_29_97_DF, 0.0, "utc"), Rate.FPS_29_97_DF)
            # the stage's clock (UTC, no offset), not the rig's own (+1 h): within the request's time
            assert abs(tc.frames_between(label, now, Rate.FPS_29_97_DF)) < 15
    finally:
        beat.terminate()
        beat.wait(10)
    wait_for(lambda: _timecode(rigs[0])["source"] == "host", 10.0)  # stage_timeout after the last beat


def test_a_heartbeat_at_another_rate_is_counted_not_followed(broker: Broker, rigs: list[LiveServer]) -> None:
    probe = NatsProbe(broker.url)
    try:
        before = rigs[0].metric("riderlive_timecode_errors_total", 'reason="timecode_rate"')
        body = orjson.dumps({"seq": 0, "t": 0.0, "source": "test", "tc": "10:00:00:00", "tc_rate": "25"})
        probe.call(probe.transport.publish(Stage(STAGE).subject(Kind.HEARTBEAT), body))
        wait_for(lambda: rigs[0].metric("riderlive_timecode_errors_total", 'reason="timecode_rate"') == before + 1)
        assert _timecode(rigs[0])["source"] == "host"
    finally:
        probe.close()


def test_stage_record_writes_mcap(broker: Broker, rigs: list[LiveServer], tmp_path: Path) -> None:
    """``riderlive stage record --mcap``: the JetStream take as MCAP, read back by the official reader."""
    from mcap.reader import make_reader

    out = tmp_path / "m1.mcap"
    command = [sys.executable, "-m", "riderlive", "stage", "--nats", broker.url, "--stage", STAGE, "record",
               "--rig", "r0", "--take", "m1", "--seconds", "0.6", "--mcap", str(out)]  # fmt: skip
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stdout + done.stderr
    frames = int(re.search(r"(\d+) frames of rig", done.stdout).group(1))  # type: ignore[union-attr]
    with out.open("rb") as fh:
        reader = make_reader(fh)
        counts = {c.topic: 0 for c in reader.get_summary().channels.values()}  # type: ignore[union-attr]
        for _, channel, _ in reader.iter_messages():
            counts[channel.topic] += 1
        written = int({m.name: m.metadata for m in reader.iter_metadata()}["riderlive"]["frames"])
    # the frames on the take's uniform grid (export.md: a take that skipped ticks is resampled)
    assert counts == {"/tf": written, "/rider/joints": written, "/horse/joints": written}
    assert written >= frames
    # a take that does not exist: a clear error, no file
    missing = tmp_path / "none.mcap"
    command = [sys.executable, "-m", "riderlive", "stage", "--nats", broker.url, "--stage", STAGE, "export",
               "--take", "nope", "--out", str(tmp_path / "nope.csv")]  # fmt: skip
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "no take" in done.stderr and not missing.exists()
