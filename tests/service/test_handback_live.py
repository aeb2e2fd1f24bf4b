"""A failover with an armed rig costs the rider stream no more than a failover without one:
the real server, the real dynamixel-sdk on the emulated bus (a pty served from this
process, every packet timed), the guardian, a /ws/rider client.

kill -9 of the tick while the rig runs: the warm spare is promoted once the guardian has
begun its stop, so rider frames reach the client again long before the guardian's park
(2 s) ends; the park is a category 1 stop (ease to park, torque off, no goal after it),
the new generation's rig waits ``connecting`` for the hand-back without a goal of its own,
and ends ``disarmed``, never re-armed.
"""

from __future__ import annotations

import os
import re
import signal
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from riderlive.dynamixel.emulator import EmulatedBus
from riderlive.dynamixel.rig import RigConfig
from tests.dynamixel.rig_harness import is_torque_off_write
from tests.dynamixel.test_rig_drive import goal_writes, parked_since
from tests.service.live_server import LiveServer
from tests.service.producers import Follower
from tests.service.rig_server import arm_running, bench3_file, rig_server
from tests.waiting import wait_until

TOKEN = "handback-token"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
PARK_S = 2.0
"""The rig's park time: the guardian eases the rig to park over this (s)."""


def rig_file(tmp_path: Path) -> Path:
    """bench3 with a short soft start, its 2 s park and generous bus budgets (a loaded host)."""
    settings = {"reply_budget_s": "0.3", "bus_watchdog_ms": "600", "soft_start_s": "0.3", "park_s": str(PARK_S)}
    return bench3_file(tmp_path, settings, timeout_margin_ms=40.0)


@pytest.fixture
def armed_rig(tmp_path: Path) -> Iterator[tuple[LiveServer, EmulatedBus, RigConfig]]:
    # the tick at its documented real-time priority (a saturated host starves it otherwise)
    tick = "rate = 100.0\nspare_nice = 0\n"
    with rig_server(tmp_path, rig_file(tmp_path), tick, TOKEN, record_arrivals=True, log_lines=80) as served:
        yield served


@pytest.mark.timeout(1800)
def test_kill_9_with_the_rig_armed_frames_flow_before_the_park_ends_and_the_rig_ends_disarmed(
    armed_rig: tuple[LiveServer, EmulatedBus, RigConfig],
) -> None:
    live, emu, rig = armed_rig
    rig_state = lambda: live.devices()["devices"][0]["state"]  # noqa: E731
    for _ in range(3):  # a loaded host may fail the tick over by itself (a hang): then arm again
        arm_running(live)
        # A spare's warm-up (imports, compiled kernels) took minutes at load 19 on the 2 shared cores.
        wait_until(lambda: live.devices()["supervision"]["spare"]["state"] == "warm", 900.0, "no warm spare")
        if rig_state() == "running":
            break
    else:
        pytest.fail(f"the host failed the tick over before every kill: {live.devices()}")
    # now: minutes of warm-up beside a FIFO emulator thread could leave it behind
    client = Follower(live.ws, horse_channels=None, max_size=None, ping_interval=None)  # closed with the server
    wait_until(lambda: len(client.frames) >= 50, 10.0, "no rider frames at the client")
    running = len(goal_writes(emu))
    wait_until(lambda: len(goal_writes(emu)) >= running + 50, 10.0, "the rig is not driven")

    before = live.devices()["supervision"]
    killed = time.perf_counter()
    os.kill(before["tick_pid"], signal.SIGKILL)
    # While the guardian parks: the new generation up, its rig waiting for the hand-back.
    samples: list[tuple[float, dict[str, Any]]] = []

    def torque_off_since_kill() -> bool:
        samples.append((time.perf_counter(), live.devices()))
        return any(t > killed and is_torque_off_write(raw) for t, raw in list(emu.arrivals))

    wait_until(torque_off_since_kill, 60.0, lambda: samples[-1], poll=0.03)
    first = client.first_ticked_after(killed)
    first_frame = None if first is None else client.frames[first]["at"]
    goals, off = parked_since(emu, rig, killed)  # eased to park, torque off, no goal after, read back off
    park_ended = off[0]
    last = {k: client.frames[-1][k] for k in ("at", "t")} if client.frames else None
    assert first_frame is not None, ("no rider frame before the park ended", len(client.frames), last, killed)
    frames_after, park_after = first_frame - killed, park_ended - killed
    print(f"kill -> first new frame at the client {frames_after * 1e3:.0f} ms; -> park ended {park_after * 1e3:.0f} ms")
    supervision = samples[-1][1]["supervision"]
    marks = {k: round((supervision[k] - killed) * 1e3) for k in ("last_down_at", "promoted_at")}
    said = [line.strip() for line in live.log if re.search(r"took over in|is up, |category 1 stop", line)]
    print(f"ms after the kill: {marks}; {said[-3:]}")
    assert park_after >= 0.75 * PARK_S, "the guardian eased toward park over most of the park time"
    assert frames_after < 1.0 and first_frame < park_ended - 0.5, (frames_after, park_after, marks, said[-3:])
    assert goals[0] - killed < 1.0, "the guardian's first park goal"

    generation = before["generation"]
    assert supervision["generation"] == generation + 1 and supervision["takeovers"] == before["takeovers"] + 1
    assert supervision["promoted_at"] - supervision["last_down_at"] < 0.5 * PARK_S, "promoted while the park went on"
    waiting = [
        s
        for t, s in samples
        if s["supervision"]["up"] and s["devices"][0]["state"] == "connecting" and first_frame < t < park_ended
    ]
    assert waiting, [s["devices"] for _, s in samples]
    detail = waiting[-1]["devices"][0]["detail"]
    assert detail.startswith(
        f"waiting for the guardian to park and hand back generation {generation} (guardian: parking"
    ), detail

    wait_until(lambda: rig_state() == "disarmed", 30.0, live.devices)
    shown = live.devices()["devices"][0]
    assert shown["counters"]["handback_waits"] == 1 and shown["counters"].get("handback_timeouts", 0) == 0
    assert shown["counters"].get("arms", 0) == 0 and shown["armed_by"] is None  # never re-armed
    ticks = lambda: live.devices()["devices"][0]["counters"]["ticks"]  # noqa: E731
    idle_from = ticks()
    wait_until(lambda: ticks() >= idle_from + 50, 10.0, "the new generation ticks its rig")  # half a second
    assert rig_state() == "disarmed"
    late_goals = [t for t, _ in goal_writes(emu) if t > park_ended]
    assert not late_goals, "no goal after the park's torque off: not the guardian's, not the new generation's"
    assert live.get("/readyz").status_code == 200 and live.metric("riderlive_tick_up") == 1
