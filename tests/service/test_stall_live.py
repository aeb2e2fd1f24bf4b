"""A reply the host carries late is not a hung tick: the real server at 120 Hz, the real
dynamixel-sdk on the emulated bus (a pty served from this process), the guardian.

The emulator's ``lag`` fault hands one servo's reply to the host over 80 ms, a byte at a
time (the serial path of a starved host: docs/hardware.md, "A busy host"); meanwhile the
tick's read times out, the next tick drains the late bytes and reads again: bounded
device waits, each declared on the safety board (``devices/iowait.py``), with the hang
threshold at its tightest (``tick.hang_ticks = 3``: 54.8 ms here). No hang, no failover,
the rig still running, each late reply counted by the device layer (``read_failures``).

Not shown here: a gap *past* the threshold made of such waits (the soak's 62-66 ms ones).
A reply of a few bytes dribbled over 80 ms leaves the drain quiet long enough to end
early, so the gaps stayed under the threshold (``io_waits_excused`` 0 in 3 runs); the
discount of longer gaps is tested on the soak's own figures in ``test_stall_io.py``.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from riderlive.dynamixel.emulator import EmulatedBus
from riderlive.dynamixel.emulator.faults import parse_fault
from riderlive.dynamixel.rig import RigConfig
from tests.service.live_server import LiveServer
from tests.service.rig_server import arm_running, bench3_file, rig_server
from tests.waiting import wait_until

TOKEN = "stall-token"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
LAGS = 6
"""Lagged replies injected, one at a time."""


def rig_file(tmp_path: Path) -> Path:
    """bench3 with budgets that leave the servos' judgement out of it (a 2 s reply budget, a
    600 ms Bus Watchdog, the bus's error budget at its largest) and long bounded waits: an
    adapter latency of 3 ms, a reply allowance of 25 ms (as a loaded host teaches the reply
    timer). The error budget: with the emulator's thread starved on a loaded host (load 13
    on the 2 cores) the replies themselves came late, 7 to 98 failed reads a run, and once
    20 more failed than good in a row: a ``bus_errors`` fault, the rig parked, not what is
    tested here."""
    settings = {
        "reply_budget_s": "2.0",
        "bus_watchdog_ms": "600",
        "bus_error_burst": "10000",
        "soft_start_s": "0.3",
        "latency_timer_ms": "3.0",
    }
    return bench3_file(tmp_path, settings, timeout_margin_ms=25.0)


@pytest.fixture
def lagging_rig(tmp_path: Path) -> Iterator[tuple[LiveServer, EmulatedBus, RigConfig]]:
    """The server as installed on a busy host (docs/hardware.md, "A busy host"): the kernel's
    tty workers raised (``kernel_workers_priority = 1``; root). Without, with the host
    loaded (load 14-17) the tick's ``select`` on the pty waited for a starved worker in
    ``__flush_work`` (state D) past its declared wait, 87 ms without a beat: a hang and a
    failover (2 of 5 runs), the starved serial path this test does not test (the lag fault
    stands for it)."""
    tick = "rate = 120.0\nhang_ticks = 3.0\nspare_nice = 0\n"
    with rig_server(tmp_path, rig_file(tmp_path), tick, TOKEN, kernel_workers=1) as served:
        yield served


@pytest.mark.timeout(1800)
def test_a_reply_carried_late_is_a_counted_device_wait_not_a_hang(
    lagging_rig: tuple[LiveServer, EmulatedBus, RigConfig],
) -> None:
    live, emu, _ = lagging_rig
    arm_running(live)
    # The realtime hang threshold needs a warm spare (without one a failover is a cold start).
    wait_until(lambda: live.devices()["supervision"]["spare"]["state"] == "warm", 900.0, "no warm spare")
    before = live.devices()
    threshold = before["supervision"]["hang_threshold"]
    assert threshold < 0.080, f"the realtime threshold at 120 Hz with hang_ticks 3: {threshold}"
    for n in range(1, LAGS + 1):
        emu.apply(parse_fault("lag:2:80"))
        wait_until(lambda n=n: emu.stats.lagged_replies >= n, 10.0, "the lagged reply was not asked for")
        reads = live.devices()["devices"][0]["counters"].get("reads", 0)
        wait_until(
            lambda r=reads: live.devices()["devices"][0]["counters"].get("reads", 0) >= r + 3,
            10.0,
            lambda: (live.devices()["devices"][0], emu.stats),
        )
    after = live.devices()
    sup, was = after["supervision"], before["supervision"]
    keys = ("hangs", "restarts", "takeovers", "stalls", "io_waits_excused", "io_wait_longest", "hang_threshold")
    print({k: sup[k] for k in keys}, after["devices"][0]["counters"], emu.stats)
    assert sup["hangs"] == was["hangs"] and sup["restarts"] == was["restarts"], sup["last_hang"]
    assert sup["takeovers"] == was["takeovers"] and sup["generation"] == was["generation"]
    assert sup["io_waits_excused"] >= was["io_waits_excused"] and sup["io_wait_longest"] >= 0.0
    assert emu.stats.lagged_replies == LAGS
    shown = after["devices"][0]
    assert shown["state"] == "running", shown
    failed = shown["counters"].get("read_failures", 0) - before["devices"][0]["counters"].get("read_failures", 0)
    assert failed >= LAGS, "each lagged reply cost its read (the device layer counts it)"
