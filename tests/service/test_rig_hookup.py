"""The tick drives a Dynamixel rig: the real service, the real dynamixel-sdk, the emulated bus.

Skipped until ``riderlive.dynamixel.driver`` (the rig helper's branch) is merged.
"""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("riderlive.dynamixel.driver")

from tests.service.live_server import ROOT, LiveServer


def rig_state(live: LiveServer) -> str | None:
    rig = live.get("/api/state").json()["tick"].get("rig")
    return None if rig is None else str(rig.get("state"))


def wait_state(live: LiveServer, wanted: set[str], timeout: float = 15.0) -> str:
    deadline = time.perf_counter() + timeout
    state = None
    while time.perf_counter() < deadline:
        state = rig_state(live)
        if state in wanted:
            return state
        time.sleep(0.1)
    raise AssertionError(f"rig state {state!r}, wanted {wanted}: {live.get('/api/state').json()['tick']}")


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


def test_serve_runs_estops_resets_and_parks_an_emulated_rig(tmp_path: Path) -> None:
    rig_file = relaxed_rig(tmp_path)
    emu = subprocess.Popen(
        [sys.executable, "-m", "riderlive", "servo-emu", "--rig", str(rig_file)],
        stdout=subprocess.PIPE,
        text=True,
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
    )
    try:
        assert emu.stdout is not None
        port = None
        for line in emu.stdout:
            match = re.match(r"port: (\S+)", line)
            if match:
                port = match.group(1)
                break
        assert port
        config = f'[tick]\nrate = 100.0\nrealtime_priority = false\n[rig]\nfile = "{rig_file}"\nport = "{port}"\n'
        live = LiveServer(config, tmp_path)
        try:
            wait_state(live, {"running"})
            rig = live.get("/api/state").json()["tick"]["rig"]
            assert rig["servos"] and all(s["present_deg"] is not None for s in rig["servos"])
            live.request("POST", "/api/estop")
            wait_state(live, {"estop"}, timeout=2.0)
            live.request("POST", "/api/reset")
            wait_state(live, {"running"})
            live.proc.send_signal(signal.SIGTERM)
            live.proc.wait(20)
        finally:
            live.stop()
        log = "".join(live.log)
        assert "Traceback" not in log, log
    finally:
        emu.terminate()
        emu.wait(10)
