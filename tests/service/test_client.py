"""riderlive.client and the examples against the real server, including a restart."""

from __future__ import annotations

import asyncio
import subprocess
import sys
from pathlib import Path

import numpy as np

from riderlive.channels import HORSE_NAMES
from riderlive.client import HorseProducer, RiderSubscriber
from riderlive.framefile import FrameTable, read_frames, write_frames
from tests.children import popen
from tests.service.conftest import BASE_CONFIG
from tests.service.live_server import ROOT, LiveServer


def test_producer_and_subscriber_round_trip(server: LiveServer) -> None:
    async def scenario() -> tuple[list, bool | None]:
        sub = RiderSubscriber(server.ws, channels=["head.rz"], horse_channels=["rearPivot.rz"], rate=100)
        got = []
        async with HorseProducer(server.ws, name="client-test") as horse:
            async for frame in sub.frames():
                await horse.send(frame.t, {"rearPivot.rz": 7.0})
                got.append(frame)
                if len(got) > 60:
                    sub.close()
            return got, horse.driving

    frames, driving = asyncio.run(scenario())
    assert driving is True
    assert set(frames[-1].values) == {"head.rz"} and frames[-1].horse == {"rearPivot.rz": 7.0}
    assert frames[-1].driver == "input"


def test_subscriber_reconnects_to_a_restarted_server(tmp_path: Path) -> None:
    first = LiveServer(BASE_CONFIG, tmp_path)
    port = first.port

    async def scenario() -> RiderSubscriber:
        sub = RiderSubscriber(first.ws, channels=["head.rz"])
        sessions = []
        async for frame in sub.frames():
            if not sessions or sessions[-1] != sub.hello["session"]:
                sessions.append(sub.hello["session"])
                if len(sessions) == 1:
                    await asyncio.to_thread(first.stop)
                    await asyncio.to_thread(restart, port)
                else:
                    assert frame.values["head.rz"] == frame.values["head.rz"]
                    sub.close()
        return sub

    servers = []

    def restart(p: int) -> None:
        # The same port again: a fresh server with a new session.
        (tmp_path / "again").mkdir()
        servers.append(LiveServer(BASE_CONFIG, tmp_path / "again", port=p))

    try:
        sub = asyncio.run(asyncio.wait_for(scenario(), 40))
        assert sub.restarted and sub.reconnects >= 1
    finally:
        for s in servers:
            s.stop()


def test_examples_stream_a_csv_in_and_record_rider_frames_out(server: LiveServer, tmp_path: Path) -> None:
    t = np.arange(0, 1.5, 1 / 60)
    values = np.zeros((len(t), len(HORSE_NAMES)))
    values[:, HORSE_NAMES.index("rearPivot.rz")] = 5.0
    horse_csv = tmp_path / "horse.csv"
    write_frames(str(horse_csv), FrameTable(HORSE_NAMES, values, t))
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    streamer = popen(
        [sys.executable, str(ROOT / "examples/stream_horse_csv.py"), str(horse_csv), "--url", server.ws],
        env=env,
    )
    out = tmp_path / "rider.csv"
    subprocess.run(
        [
            sys.executable,
            str(ROOT / "examples/record_rider.py"),
            str(out),
            "--url",
            server.ws,
            "--seconds",
            "1",
            "--channels",
            "head.rz,cog.ty",
        ],
        env=env,
        check=True,
        timeout=30,
    )
    assert streamer.wait(30) == 0
    rider = read_frames(str(out))
    assert rider.names == ("head.rz", "cog.ty") and len(rider) > 100


def test_examples_give_a_one_line_error_within_the_timeout_counted_from_start(tmp_path: Path) -> None:
    """A host that takes the connection and never answers: each example exits 2 with one line on
    stderr within its --timeout counted from the process's start, imports included (it took 15 s)."""
    import socket
    import time

    horse_csv = tmp_path / "horse.csv"
    write_frames(str(horse_csv), FrameTable(HORSE_NAMES, np.zeros((2, len(HORSE_NAMES))), np.array([0.0, 0.01])))
    silent = socket.socket()
    silent.bind(("127.0.0.1", 0))
    silent.listen(8)  # the kernel completes the TCP handshake; nobody ever answers the websocket's
    url = f"ws://127.0.0.1:{silent.getsockname()[1]}"
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    try:
        for example, first in (("stream_horse_csv.py", str(horse_csv)), ("record_rider.py", str(tmp_path / "r.csv"))):
            start = time.monotonic()
            proc = subprocess.run(
                [sys.executable, str(ROOT / "examples" / example), first, "--url", url, "--timeout", "3"],
                env=env,
                capture_output=True,
                text=True,
                timeout=30,
            )
            elapsed = time.monotonic() - start
            assert proc.returncode == 2, proc.stderr
            lines = proc.stderr.strip().splitlines()
            assert len(lines) == 1 and "cannot reach riderlive" in lines[0] and "no answer within" in lines[0], lines
            # 3 s from the process's start (0.5 s more only where start-up alone outlasts it), and its exit.
            assert elapsed < 3.0 + 1.5, f"{example}: {elapsed:.2f} s"  # 3.0-3.3 s measured at load 25
    finally:
        silent.close()
