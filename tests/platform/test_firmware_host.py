"""The firmware's host build as riderlive starts it: the CLI, the e-stop input and a stuck
actuator set from its stdin, seen through the link."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import pytest

from riderlive.platform import link, link_vocab
from riderlive.platform.firmware_host import FirmwareHost
from riderlive.platform.link_vocab import Fault, LinkState, Reason
from riderlive.platform.serial_link import CommandRefused, SerialPlatformLink
from tests.waiting import Pacer


def stream(port: SerialPlatformLink, state: LinkState, positions: list[int], timeout_s: float) -> link.Telemetry:
    deadline, pacer = time.monotonic() + timeout_s, Pacer(0.004)
    while port.telemetry is None or LinkState(port.telemetry.state) is not state:
        assert time.monotonic() < deadline, f"still {port.state.label}"
        port.send_targets(positions)
        port.service()
        pacer.wait()  # the host's target rate (250 Hz)
    return port.telemetry


def test_cli_runs_the_host_build_and_prints_its_pty() -> None:
    args = ["firmware-emu", "--profile", "servo8", "--name", "puppet", "--duration", "0.3"]
    out = subprocess.run(
        [sys.executable, "-m", "riderlive", *args],
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    ).stdout.splitlines()
    ready, last = json.loads(out[0]), json.loads(out[-1])
    assert ready["event"] == "ready" and ready["port"].startswith("/dev/pts/")
    assert (ready["profile"], ready["device"], ready["actuators"], ready["period_ms"]) == ("servo8", "puppet", 8, 4)
    assert last["event"] == "status" and last["state"] == "disarmed" and last["outputs_on"] == 0


def test_the_estop_input_latches_and_holds_reset_off() -> None:
    with FirmwareHost("servo8") as firmware, SerialPlatformLink(firmware.port) as port:
        port.open()
        port.command(link.Config(link_vocab.ConfigKey.HEARTBEAT_TIMEOUT_MS, 0, 1000))  # not the dead-man's test
        port.command(link.Arm("servo8"))
        stream(port, LinkState.RUNNING, [2000] * 8, 5.0)
        firmware.send("estop on")
        seen = port.wait_telemetry(lambda t: LinkState(t.state) is LinkState.ESTOP, 2.0)
        assert seen.faults == Fault.ESTOP_INPUT and seen.flags & link_vocab.Flag.ESTOP_INPUT
        assert not seen.flags & link_vocab.Flag.OUTPUTS_ON
        with pytest.raises(CommandRefused) as refused:
            port.command(link.Reset())
        assert refused.value.reason is Reason.ESTOP_INPUT
        firmware.send("estop off")
        port.wait_telemetry(lambda t: not t.flags & link_vocab.Flag.ESTOP_INPUT, 2.0)
        assert port.command(link.Reset()).state == LinkState.DISARMED
        assert port.command(link.Arm("servo8")).state == LinkState.SOFT_START


def test_a_stuck_actuator_is_a_following_error() -> None:
    with FirmwareHost("platform6") as firmware, SerialPlatformLink(firmware.port) as port:
        port.open()
        port.command(link.Config(link_vocab.ConfigKey.HEARTBEAT_TIMEOUT_MS, 0, 1000))
        port.command(link.Arm("platform6"))
        stream(port, LinkState.RUNNING, [7500] * 6, 10.0)
        firmware.send("stick 3")
        faulted = stream(port, LinkState.FAULT, [11000] * 6, 10.0)
        assert faulted.faults == Fault.FOLLOWING_ERROR and not faulted.flags & link_vocab.Flag.OUTPUTS_ON
        assert abs(faulted.measured[3] - 7500) < 50  # it never moved
        assert "parking" in firmware.states()
