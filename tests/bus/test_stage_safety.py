"""Three rigs on one stage, each driving an emulated Dynamixel bus (``riderlive servo-emu`` on
a pty, its own process) through the real SDK:

- the stage e-stop on NATS reaches every rig: each latches, torque off on every servo (read
  back from the bus by the rig: ``outputs_off_confirmed``);
- the broker killed mid-move: no more stage heartbeat, so every armed rig parks (ease to
  park, then torque off; never frozen mid-move, never an e-stop), a local take being
  recorded keeps growing and ends complete, each service reconnects when the broker is
  back, and nothing re-arms.
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Iterator
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest

from riderlive.bus.broker import Broker
from riderlive.bus.stage import beat, stage_estop
from riderlive.bus.subjects import Stage
from riderlive.takes.recorder import read_sidecar
from tests.bus.harness import TOKEN, NatsProbe, start_rig, wait_for
from tests.dynamixel.rig_harness import servo_emulator
from tests.service.live_server import LiveServer
from tests.service.test_rig_hookup import relaxed_rig

pytestmark = pytest.mark.slow
STAGE = Stage("S")
AUTH = {"Authorization": f"Bearer {TOKEN}"}
HEARTBEAT_TIMEOUT = 0.5


@dataclass
class Rig:
    name: str
    live: LiveServer

    def status(self) -> dict:
        return dict(self.live.get("/api/state", headers=AUTH).json()["tick"].get("rig") or {})

    def state(self) -> str:
        return str(self.status().get("state"))

    def wait_ticks(self, ticks: int) -> None:
        """Until the rig has been ticked ``ticks`` more times (a span of its tick's own time)."""
        start = self.status()["counters"]["ticks"]
        wait_for(lambda: self.status()["counters"]["ticks"] >= start + ticks, 10.0, self.status)

    def torque_off(self) -> bool:
        """The rig read torque-enable back as 0 on every servo."""
        return self.status().get("outputs_off_confirmed") is True

    def post(self, path: str, body: dict | None = None) -> httpx.Response:
        return self.live.request("POST", path, json=body, headers=AUTH)

    def metric(self, name: str, labels: str) -> float:
        for line in self.live.get("/metrics", headers=AUTH).text.splitlines():
            if line.startswith(f"{name}{{{labels}}} "):
                return float(line.rsplit(" ", 1)[1])
        return 0.0


@dataclass
class Stage3:
    broker: Broker
    rigs: list[Rig]
    probe: NatsProbe
    beating: threading.Event

    def wait_all(self, wanted: str, timeout: float = 15.0) -> None:
        for rig in self.rigs:
            wait_for(
                lambda r=rig: r.state() == wanted, timeout, lambda r=rig: (r.name, wanted, r.status(), r.live.log[-15:])
            )


@pytest.fixture(scope="module")
def stage3(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Stage3]:
    root = tmp_path_factory.mktemp("stage3")
    rig_file = relaxed_rig(root)
    with ExitStack() as stack:
        broker = stack.enter_context(Broker())
        ports = [emulator(stack, rig_file) for _ in range(3)]
        config = (
            f'[tick]\nrate = 50.0\nrealtime_priority = false\n[security]\ntoken = "{TOKEN}"\n'
            f'[rig]\nfile = "{rig_file}"\n'
        )
        lives: list[LiveServer | None] = [None] * 3
        errors: list[BaseException] = []

        def launch(i: int) -> None:
            try:
                text = config + f'port = "{ports[i]}"\n'
                extra = f"heartbeat_timeout = {HEARTBEAT_TIMEOUT}"
                lives[i] = start_rig(root / f"r{i}", broker.url, STAGE.name, f"r{i}", text, extra, token=TOKEN)
            except BaseException as exc:  # reported below
                errors.append(exc)

        threads = [threading.Thread(target=launch, args=(i,)) for i in range(3)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(90)
        for live in lives:
            if live is not None:
                stack.callback(live.stop)
        assert not errors, errors
        probe = NatsProbe(broker.url)
        stack.callback(probe.close)
        beating = threading.Event()
        stop = asyncio.Event()

        async def heart() -> None:
            beating.set()
            await beat(probe.transport, STAGE, 0.05, stop)

        probe.start(heart)
        rigs = [Rig(f"r{i}", live) for i, live in enumerate(lives) if live is not None]
        yield Stage3(broker, rigs, probe, beating)
        for rig in rigs:
            assert "Traceback" not in "".join(rig.live.log), "".join(rig.live.log)


def emulator(stack: ExitStack, rig_file: Path) -> str:
    """``riderlive servo-emu --rig FILE`` in its own process, stopped with ``stack``; its pty."""
    return stack.enter_context(servo_emulator(rig_file))


def arm_all(stage: Stage3) -> None:
    stage.wait_all("disarmed")
    for rig in stage.rigs:  # the heartbeat may need a moment to be heard
        wait_for(
            lambda r=rig: r.post("/api/arm", {"device": "bench3"}).status_code == 200,
            5.0,
            lambda r=rig: r.post("/api/arm", {"device": "bench3"}).text,
        )
    stage.wait_all("running")
    for rig in stage.rigs:
        assert not rig.torque_off(), rig.name


def test_the_stage_estop_reaches_every_rig_and_turns_every_torque_off(stage3: Stage3) -> None:
    arm_all(stage3)
    sent = time.perf_counter()
    acks = stage3.probe.call(stage_estop(stage3.probe.transport, STAGE, "test", 1.0))
    assert sorted(a["rig"] for a in acks) == ["r0", "r1", "r2"]
    stage3.wait_all("estop", timeout=5.0)
    for rig in stage3.rigs:
        wait_for(rig.torque_off, 3.0, rig.status)
        estop = rig.status()["estop"]
        assert estop["source"] == "nats" and estop["confirmed"] is True
        assert estop["confirmed_at"] - sent < 2.0, estop  # bench/bench_nats.py measures it
        assert rig.metric("riderlive_nats_events_total", 'event="estops"') == 1
    # the latch holds until each rig is reset on its own; reset never arms
    for rig in stage3.rigs:
        assert rig.post("/api/reset").status_code == 200
    stage3.wait_all("disarmed")
    for rig in stage3.rigs:
        # read back off (a read-back a busy host kept the servos from answering is repeated,
        # every tick for a second, then every 0.5 s: devices/off_readback.py)
        wait_for(rig.torque_off, 3.0, rig.status)
        rig.wait_ticks(30)
    statuses = [rig.status() for rig in stage3.rigs]
    shown = [(rig.name, s["state"], s.get("outputs_off_confirmed")) for rig, s in zip(stage3.rigs, statuses)]
    assert all(s["state"] == "disarmed" and s.get("outputs_off_confirmed") is True for s in statuses), shown


def test_a_dead_broker_parks_every_rig_keeps_the_take_and_nothing_rearms(stage3: Stage3) -> None:
    arm_all(stage3)
    first = stage3.rigs[0]
    assert first.post("/api/record/start", {"name": "during-outage"}).status_code == 200
    seen: dict[str, set[str]] = {rig.name: set() for rig in stage3.rigs}
    stage3.broker.kill()
    killed = time.perf_counter()

    def parked() -> bool:
        for rig in stage3.rigs:
            seen[rig.name].add(rig.state())
        return all(rig.state() == "parked" for rig in stage3.rigs)

    def why() -> dict[str, object]:  # each rig still not parked: its stage link and its last log lines
        return {
            r.name: (
                r.state(),
                [m for m in r.live.get("/metrics", headers=AUTH).text.splitlines() if m.startswith("riderlive_nats")],
                r.live.log[-15:],
            )
            for r in stage3.rigs
            if r.state() != "parked"
        }

    wait_for(parked, 15.0, why)
    took = time.perf_counter() - killed
    assert took > HEARTBEAT_TIMEOUT  # not before the heartbeat was really missed
    for rig in stage3.rigs:
        wait_for(rig.torque_off, 3.0, rig.status)  # parked: torque off, read back
        assert seen[rig.name] <= {"running", "parking", "parked"}, seen  # a controlled stop, no e-stop, no fault
        assert rig.metric("riderlive_nats_events_total", 'event="heartbeat_stops"') >= 1
    rows = lambda: first.live.get("/api/state", headers=AUTH).json()["recording"]["rows"]  # noqa: E731
    before = rows()
    wait_for(lambda: rows() > before, 5.0, rows)  # the take goes on
    # arming is refused while the stage is silent
    refused = first.post("/api/arm", {"device": "bench3"})
    assert refused.status_code == 409 and "heartbeat" in refused.json()["detail"]["message"]

    stage3.broker.start()  # the same port, as a restarted broker
    for rig in stage3.rigs:
        wait_for(lambda r=rig: r.metric("riderlive_nats_events_total", 'event="reconnects"') >= 1, 15.0)
        wait_for(lambda r=rig: r.metric("riderlive_nats_events_total", 'event="heartbeat_back"') >= 1, 15.0)
    for rig in stage3.rigs:
        rig.wait_ticks(50)
    assert all(rig.state() == "parked" for rig in stage3.rigs)  # nothing re-arms
    take = first.post("/api/record/stop").json()["take"]
    meta = read_sidecar(Path(take["path"]) if Path(take["path"]).is_absolute() else first.live.workdir / take["path"])
    assert meta is not None and meta["complete"] is True and take["rows"] > 50
