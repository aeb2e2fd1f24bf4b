"""The real server driving bench3 on the emulated bus (a pty served from this process): the
shared set-up of the live rig tests (``test_handback_live``, ``test_stall_live``).

:func:`bench3_file` writes bench3 with the test's own budgets; :func:`rig_server` starts the
emulator (its thread at SCHED_FIFO 30 where allowed: hardware is not starved by the host's
load) and ``riderlive serve`` with the rig, yields both, and on the way out stops them, prints
the server's last log lines (shown when the test fails) and asserts it logged no traceback.

:func:`relaxed_rig` and :func:`serve_rig`: bench3 with short ramps and generous budgets, served
with the emulator in its own process (``test_rig_hookup``; the session's ``shared_rig`` of
``conftest.py`` for tests that only arm it and look).
"""

from __future__ import annotations

import contextlib
import os
import re
import sys
from collections import deque
from collections.abc import Iterator, Mapping
from pathlib import Path

from riderlive.dynamixel.emulator import EmulatedBus
from riderlive.dynamixel.rig import RigConfig, load_rig
from tests.dynamixel.rig_harness import servo_emulator, servo_setups
from tests.service.live_server import ROOT, LiveServer
from tests.waiting import wait_until

RIG_TOKEN = "rig-token-123"
"""The token of :func:`serve_rig`'s server."""


def bench3_file(tmp_path: Path, settings: Mapping[str, str], timeout_margin_ms: float) -> Path:
    """``config/rigs/bench3.toml`` with each ``key = value`` of ``settings`` replaced (a bus
    key the file leaves at its default is added to ``[bus]``) and the bus's
    ``timeout_margin_ms`` set, written to ``tmp_path``."""
    text = (ROOT / "config" / "rigs" / "bench3.toml").read_text()
    for key, value in (settings | {"timeout_margin_ms": str(timeout_margin_ms)}).items():
        text, found = re.subn(rf"^{key} = .*$", f"{key} = {value}", text, flags=re.M)
        if not found:
            text = text.replace("[bus]\n", f"[bus]\n{key} = {value}\n", 1)
    path = tmp_path / "bench3.toml"
    path.write_text(text)
    return path


@contextlib.contextmanager
def rig_server(
    tmp_path: Path,
    path: Path,
    tick: str,
    token: str,
    *,
    record_arrivals: bool = False,
    log_lines: int = 60,
    kernel_workers: int = 0,
) -> Iterator[tuple[LiveServer, EmulatedBus, RigConfig]]:
    """The server with the rig of ``path`` on a fresh emulator; ``tick`` is the ``[tick]``
    table's body (TOML lines); ``record_arrivals`` keeps every packet of the run, timed;
    ``kernel_workers``: ``[host] kernel_workers_priority`` (0: the default, off)."""
    rig = load_rig(path)
    switch = sys.getswitchinterval()
    sys.setswitchinterval(0.0002)  # the emulator's thread answers the tick's SDK in time
    emu = EmulatedBus(servo_setups(rig), baud=rig.bus.baud)
    if record_arrivals:
        emu.arrivals = deque(maxlen=200_000)
    emu.start()
    assert emu._thread is not None and emu._thread.native_id is not None
    with contextlib.suppress(PermissionError, OSError):  # hardware is not starved by the host's load
        os.sched_setscheduler(emu._thread.native_id, os.SCHED_FIFO, os.sched_param(30))
    config = f'[tick]\n{tick}[security]\ntoken = "{token}"\n[rig]\nfile = "{path}"\nport = "{emu.port}"\n'
    config += f"[host]\nkernel_workers_priority = {kernel_workers}\n" if kernel_workers else ""
    live = LiveServer(config, tmp_path, token=token)
    try:
        yield live, emu, rig
    finally:
        live.stop()
        emu.stop()
        print("".join(live.log[-log_lines:]))  # shown when the test fails
        sys.setswitchinterval(switch)
        assert "Traceback" not in "".join(live.log), "".join(live.log)


def relaxed_rig(tmp_path: Path) -> Path:
    """bench3 with short ramps and generous bus budgets (this machine may be saturated)."""
    text = (ROOT / "config" / "rigs" / "bench3.toml").read_text()
    for key, value in (
        ("reply_budget_s", "0.3"),
        ("bus_watchdog_ms", "600"),
        ("soft_start_s", "0.3"),
        ("park_s", "0.3"),
    ):
        text = re.sub(rf"^{key} = .*$", f"{key} = {value}", text, flags=re.M)
    text = text.replace("[bus]\n", "[bus]\ntimeout_margin_ms = 40.0\n", 1)
    path = tmp_path / "bench3.toml"
    path.write_text(text)
    return path


@contextlib.contextmanager
def serve_rig(tmp_path: Path, spare: bool) -> Iterator[LiveServer]:
    """The server driving bench3 (:func:`relaxed_rig`) on the emulated bus; ``spare``: ``tick.spare``."""
    rig_file = relaxed_rig(tmp_path)
    with servo_emulator(rig_file) as port:
        config = (
            f"[tick]\nrate = 100.0\nrealtime_priority = false\nspare = {str(spare).lower()}\n"
            f'[security]\ntoken = "{RIG_TOKEN}"\n[rig]\nfile = "{rig_file}"\nport = "{port}"\n'
        )
        live = LiveServer(config, tmp_path, token=RIG_TOKEN)
        try:
            yield live
        finally:
            live.stop()
            assert "Traceback" not in "".join(live.log), "".join(live.log)


def arm_running(live: LiveServer, device: str = "bench3") -> None:
    """Once ``device`` may be armed (disarmed or parked, the guardian alive): arm it by REST
    and wait until it runs."""

    def state() -> str:
        return str(live.devices()["devices"][0]["state"])

    wait_until(lambda: state() in ("disarmed", "parked"), 60.0, live.devices)
    live.wait_guardian()
    armed = live.request("POST", "/api/arm", json={"device": device}, headers=live.auth)
    assert armed.status_code == 200, armed.text
    wait_until(lambda: state() == "running", 30.0, live.devices)
