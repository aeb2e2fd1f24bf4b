"""Several hosts in network namespaces (``ip netns``, veth pairs): a NATS server and the stage
heartbeat in one, two rigs and an engine subscriber in others. The engine receives both
rigs' frames across the links; a link cut with ``ip link set down`` makes that rig lose
the stage (its heartbeat stops: it logs the loss and would park) while the other rig
carries on; with the link back up the rig rejoins by itself.

Skipped, with the reason, where namespaces cannot be made (not root, no ``ip``, a
container without CAP_SYS_ADMIN).
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from riderlive.bus.broker import Broker
from tests.service.live_server import ROOT
from tests.waiting import wait_until

pytestmark = pytest.mark.slow
SUFFIX = f"{os.getpid() % 100000}"
SERVER, RIG_A, RIG_B, ENGINE = (f"rl{n}{SUFFIX}" for n in ("s", "a", "b", "e"))
LINKS = {RIG_A: 1, RIG_B: 2, ENGINE: 3}
"""Namespace -> its /30 to the server: 10.77.N.1 (server side), 10.77.N.2."""
ENV = {"PYTHONPATH": str(ROOT), "PATH": os.environ.get("PATH", "/usr/bin:/bin"), "PYTHONUNBUFFERED": "1"}


def ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True, timeout=10)


def netns_unavailable() -> str | None:
    if shutil.which("ip") is None:
        return "no `ip` command (iproute2)"
    if os.geteuid() != 0:
        return "network namespaces need root"
    probe = f"rlprobe{SUFFIX}"
    done = subprocess.run(["ip", "netns", "add", probe], capture_output=True, text=True)
    if done.returncode != 0:
        return f"`ip netns add` is not allowed here: {done.stderr.strip()}"
    subprocess.run(["ip", "netns", "del", probe], capture_output=True)
    return None


@dataclass
class Process:
    proc: subprocess.Popen[str]
    lines: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line)

    def wait_for(self, pattern: str, timeout: float) -> None:
        deadline = time.perf_counter() + timeout
        found = lambda: any(re.search(pattern, line) for line in self.lines)  # noqa: E731
        with contextlib.suppress(AssertionError):
            wait_until(lambda: found() or self.proc.poll() is not None, max(0.0, deadline - time.perf_counter()))
        if found():
            return
        raise AssertionError(f"no {pattern!r} in:\n{''.join(self.lines)[-3000:]}")

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(2)
            try:
                self.proc.wait(15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)


def run_in(ns: str, *command: str) -> Process:
    full = ["ip", "netns", "exec", ns, *command]
    return Process(subprocess.Popen(full, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=ENV))


ENGINE_PROBE = """
import asyncio, json, sys
from riderlive.bus.nats import connect
from riderlive.bus.stage import discover
from riderlive.bus.subjects import Kind, Stage
async def main():
    t = await connect(sys.argv[1])
    stage = Stage(sys.argv[2])
    counts = {}
    async def on(msg):
        rig = msg.subject.split(".")[3]
        counts[rig] = counts.get(rig, 0) + 1
    await t.subscribe(stage.every_rig(Kind.FRAME), on)
    await asyncio.sleep(float(sys.argv[3]))
    rigs = [r["rig"] for r in await discover(t, stage, 0.5)]
    print(json.dumps({"frames": counts, "rigs": rigs}))
    await t.close()
asyncio.run(main())
"""


TICKING_PROBE = """
import asyncio, json, sys, time
from riderlive.bus.nats import connect
from riderlive.bus.stage import discover
from riderlive.bus.subjects import Stage
async def main():
    t = await connect(sys.argv[1])
    stage, want, deadline = Stage(sys.argv[2]), set(sys.argv[4].split(",")), time.perf_counter() + float(sys.argv[3])
    while True:
        rigs = await discover(t, stage, 0.5)
        up = sorted(r["rig"] for r in rigs if r.get("tick_up"))
        if want <= set(up) or time.perf_counter() > deadline:
            break
    print(json.dumps({"up": up, "rigs": [r["rig"] for r in rigs]}))
    await t.close()
asyncio.run(main())
"""


def wait_ticking(url: str, stage: str, rigs: list[str], timeout: float = 60.0) -> None:
    """Until every rig's tick is up (its discovery status: the first heartbeat of its tick
    process, so its frames flow). A rig joins the stage before its spawned tick has beaten;
    on a loaded host that is seconds."""
    done = subprocess.run(
        ["ip", "netns", "exec", ENGINE, sys.executable, "-c", TICKING_PROBE, url, stage, str(timeout), ",".join(rigs)],
        capture_output=True,
        text=True,
        timeout=timeout + 30,
        env=ENV,
    )
    assert done.returncode == 0, done.stderr
    seen = json.loads(done.stdout.strip().splitlines()[-1])
    assert set(rigs) <= set(seen["up"]), seen


def engine_sees(url: str, stage: str, seconds: float = 2.0) -> dict:
    done = subprocess.run(
        ["ip", "netns", "exec", ENGINE, sys.executable, "-c", ENGINE_PROBE, url, stage, str(seconds)],
        capture_output=True,
        text=True,
        timeout=60,
        env=ENV,
    )
    assert done.returncode == 0, done.stderr
    return dict(json.loads(done.stdout.strip().splitlines()[-1]))


@pytest.fixture
def namespaces() -> Iterator[None]:
    why = netns_unavailable()
    if why is not None:
        pytest.skip(why)
    made: list[str] = []
    try:
        for ns in (SERVER, RIG_A, RIG_B, ENGINE):
            ip("netns", "add", ns)
            made.append(ns)
            ip("-n", ns, "link", "set", "lo", "up")
        for ns, n in LINKS.items():
            inner, outer = f"v{n}{SUFFIX}", f"s{n}{SUFFIX}"
            ip("link", "add", inner, "netns", ns, "type", "veth", "peer", "name", outer, "netns", SERVER)
            ip("-n", SERVER, "addr", "add", f"10.77.{n}.1/30", "dev", outer)
            ip("-n", ns, "addr", "add", f"10.77.{n}.2/30", "dev", inner)
            ip("-n", SERVER, "link", "set", outer, "up")
            ip("-n", ns, "link", "set", inner, "up")
        yield
    finally:
        for ns in made:
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)


def test_two_rigs_and_an_engine_across_links_and_a_cut_link(namespaces: None, tmp_path: Path) -> None:
    stage = "net"
    started: list[Process] = []
    broker = Broker(host="0.0.0.0", command_prefix=("ip", "netns", "exec", SERVER), workdir=tmp_path)
    broker.start()
    try:
        config = tmp_path / "rig.toml"
        config.write_text("[tick]\nrate = 60.0\nrealtime_priority = false\n[nats]\nheartbeat_timeout = 0.5\n")
        url_of = {ns: f"nats://10.77.{n}.1:{broker.port}" for ns, n in LINKS.items()}
        server_url = f"nats://127.0.0.1:{broker.port}"
        heart = run_in(
            SERVER, sys.executable, "-m", "riderlive", "stage", "--nats", server_url, "--stage", stage, "heartbeat"
        )
        started.append(heart)
        rigs = {}
        for ns, name in ((RIG_A, "a"), (RIG_B, "b")):
            command = [sys.executable, "-m", "riderlive", "serve", "--config", str(config), "--port", "0"]
            rigs[name] = run_in(ns, *command, "--nats", url_of[ns], "--stage", stage, "--rig", name)
            started.append(rigs[name])
        for rig in rigs.values():
            rig.wait_for("joined stage 'net'", 60.0)
        wait_ticking(url_of[ENGINE], stage, ["a", "b"])  # joined is not ticking yet
        seen = engine_sees(url_of[ENGINE], stage)
        assert seen["rigs"] == ["a", "b"]
        # 60 Hz over 2 s; this test is about the links, not the rate (a loaded machine starves rigs)
        assert seen["frames"].get("a", 0) >= 5 and seen["frames"].get("b", 0) >= 5, seen

        ip("-n", RIG_A, "link", "set", f"v{LINKS[RIG_A]}{SUFFIX}", "down")  # cut rig a's cable
        rigs["a"].wait_for("stage heartbeat lost", 10.0)
        seen = engine_sees(url_of[ENGINE], stage)
        assert seen["rigs"] == ["b"] and seen["frames"].get("b", 0) >= 5 and seen["frames"].get("a", 0) == 0, seen
        assert not any("stage heartbeat lost" in line for line in rigs["b"].lines)

        ip("-n", RIG_A, "link", "set", f"v{LINKS[RIG_A]}{SUFFIX}", "up")  # and mend it
        rigs["a"].wait_for(r"stage heartbeat back", 20.0)
        seen = engine_sees(url_of[ENGINE], stage)
        assert seen["rigs"] == ["a", "b"] and seen["frames"].get("a", 0) >= 5, seen
    finally:
        for process in reversed(started):
            process.stop()
        broker.close()
