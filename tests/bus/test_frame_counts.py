"""Every tick a rig on a stage ran is published, dropped, skipped or still queued: its
status counts them, against a real nats-server, with the web process stopped so that
ticks age out of the queue."""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Iterator
from pathlib import Path

import orjson
import pytest

from riderlive.bus.broker import Broker
from riderlive.bus.subjects import Kind, Stage
from tests.bus.harness import TOKEN, NatsProbe, start_rig, wait_for
from tests.bus.harness import TOKEN_CONFIG as CONFIG
from tests.service.live_server import LiveServer

RIG = Stage("A").rig("counts")


@pytest.fixture
def rig(broker: Broker, tmp_path: Path) -> Iterator[LiveServer]:
    live = start_rig(tmp_path, broker.url, "A", "counts", CONFIG, token=TOKEN)
    yield live
    live.stop()


def test_out_dropped_skipped_and_queued_cover_every_tick(rig: LiveServer, broker: Broker) -> None:
    probe = NatsProbe(broker.url)
    try:
        frames = probe.collect(RIG.subject(Kind.FRAME))
        wait_for(lambda: len(frames) > 20, say=lambda: len(frames))
        os.kill(rig.proc.pid, signal.SIGSTOP)  # the tick goes on; the web process reads nothing
        time.sleep(0.6)  # the stimulus: a web process stopped for 0.6 s
        os.kill(rig.proc.pid, signal.SIGCONT)
        resumed = len(frames)
        wait_for(lambda: len(frames) > resumed + 30, say=lambda: len(frames))  # publishing again
        status = orjson.loads(probe.request(RIG.subject(Kind.CONTROL), orjson.dumps({"action": "state"})))
    finally:
        probe.close()
    counts, span = status["counts"], status["frames"]
    ticks = span["last_seq"] - span["first_seq"] + 1
    accounted = counts.get("frames_out", 0) + counts.get("frames_dropped", 0) + counts.get("frames_skipped", 0)
    assert accounted + span["queued"] == ticks, status
    assert counts.get("frames_dropped", 0) + counts.get("frames_skipped", 0) > 0, "0.6 s stopped: some aged out"
