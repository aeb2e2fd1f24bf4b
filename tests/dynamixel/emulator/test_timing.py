"""Wire timing (bytes x 10 / baud plus Return Delay Time), a 24-servo bus, and the CLI."""

from __future__ import annotations

import argparse
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from dynamixel_sdk import COMM_SUCCESS, GroupSyncRead, GroupSyncWrite

from riderlive.dynamixel.emulator import EmulatedBus, ServoSetup
from riderlive.dynamixel.emulator.cli import parse_servo
from riderlive.dynamixel.tables import Item
from tests.waiting import wait_until

from ..conftest import open_sdk, rider_servos

REPO = Path(__file__).resolve().parents[2]


def best_of(fn: Callable[[], object], n: int) -> float:
    best = float("inf")
    for _ in range(n):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def test_a_ping_takes_its_wire_time_and_return_delay(bus_factory: Callable[..., EmulatedBus]) -> None:
    bus = bus_factory([ServoSetup(1, "XL330-M288")], baud=57_600, wire_timing=True)
    link = open_sdk(bus)
    assert link.ph.ping(link.port, 1)[1] == COMM_SUCCESS
    wire = (10 + 14) * 10 / 57_600  # instruction + status, 10 bits a byte
    delay = 250 * 2e-6  # the default Return Delay Time
    rtt = best_of(lambda: link.ph.ping(link.port, 1), 5)
    assert wire + delay <= rtt < wire + delay + 0.03
    bus.write_item(1, Item.RETURN_DELAY_TIME, 0)
    rtt = best_of(lambda: link.ph.ping(link.port, 1), 5)
    assert wire <= rtt < wire + 0.03
    link.close()


def test_24_servos_sync_write_and_fast_sync_read(bus_factory: Callable[..., EmulatedBus]) -> None:
    bus = bus_factory(rider_servos(24), baud=1_000_000, wire_timing=True)
    for servo in bus.servos:
        servo.set(Item.RETURN_DELAY_TIME, 0)
    link = open_sdk(bus)
    writer = GroupSyncWrite(link.port, link.ph, 116, 4)
    reader = GroupSyncRead(link.port, link.ph, 132, 4)
    for i in range(1, 25):
        writer.addParam(i, list((2048 + i).to_bytes(4, "little")))
        reader.addParam(i)
    assert link.ph.write1ByteTxRx(link.port, 0xFE, 64, 1)[0] == COMM_SUCCESS

    def tick() -> None:
        assert writer.txPacket() == COMM_SUCCESS
        assert reader.fastSyncRead() == COMM_SUCCESS

    wire = ((14 + 5 * 24) + (14 + 24) + (8 + 8 * 24)) * 10 / 1_000_000  # 3.72 ms
    assert wire <= best_of(tick, 5) < wire + 0.03

    def arrived() -> bool:  # the servos reach their goals in emulated time
        tick()
        return [reader.getData(i, 132, 4) for i in range(1, 25)] == [2048 + i for i in range(1, 25)]

    wait_until(arrived, 5.0, "the servos never reached their goals", poll=0.01)
    link.close()


def test_parse_servo() -> None:
    assert parse_servo("7:xm430-w350") == ServoSetup(7, "XM430-W350")
    assert parse_servo("7:XL330-M288:1000") == ServoSetup(7, "XL330-M288", 1000)
    for bad in ("7", "x:XL330-M288", "7:XL999", "300:XL330-M288"):
        with pytest.raises(argparse.ArgumentTypeError, match=r"servo|model"):
            parse_servo(bad)


def test_cli_serves_a_bus_and_reports(tmp_path: Path) -> None:
    link_path = tmp_path / "bus"
    cmd = [sys.executable, "-m", "riderlive", "servo-emu", "--servo", "1:xl430-w250", "--servo", "2:XL330-M288"]
    cmd += ["--duration", "20", "--link", str(link_path), "--fault", "overload:2@0"]
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, text=True, env={"PYTHONPATH": str(REPO)})
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline()
        assert first.startswith("port: /dev/pts/")
        from dynamixel_sdk import PacketHandler, PortHandler

        port = PortHandler(str(link_path))
        assert port.openPort()
        ph = PacketHandler(2.0)
        assert ph.ping(port, 1)[:2] == (1060, COMM_SUCCESS)
        wait_until(lambda: ph.read1ByteTxRx(port, 2, 70)[0] == 0x20, 2.0, "no overload error", poll=0.05)
        assert ph.read1ByteTxRx(port, 2, 70) == (0x20, COMM_SUCCESS, 0x80)
        port.closePort()
        proc.send_signal(signal.SIGINT)  # stops cleanly, like Ctrl-C
        out, _ = proc.communicate(timeout=10)
    finally:
        proc.kill()
    assert proc.returncode == 0
    assert "PING" in out and "READ" in out
    assert not link_path.exists()


def test_cli_refuses_no_servos() -> None:
    from riderlive.cli import main

    assert main(["servo-emu"]) == 2


def test_cli_reads_a_rig(tmp_path: Path) -> None:
    rig = pytest.importorskip("riderlive.dynamixel.rig")
    from riderlive.dynamixel.emulator.cli import servos_from_rig

    path = rig.RIG_DIR / "bench3.toml"
    servos, baud = servos_from_rig(str(path))
    loaded = rig.load_rig(path)
    assert [s.id for s in servos] == [s.id for s in loaded.servos.values()]
    assert baud == loaded.bus.baud
    assert all(0 <= s.position < 4096 for s in servos)


def test_return_delay_time_is_honoured_without_wire_timing(bus_factory: Callable[..., EmulatedBus]) -> None:
    bus = bus_factory([ServoSetup(1, "XL330-M288")], baud=4_000_000, wire_timing=False)
    link = open_sdk(bus)
    bus.write_item(1, Item.RETURN_DELAY_TIME, 254)  # 508 us, the register's maximum
    slow = best_of(lambda: link.ph.ping(link.port, 1), 7)
    bus.write_item(1, Item.RETURN_DELAY_TIME, 0)
    fast = best_of(lambda: link.ph.ping(link.port, 1), 7)
    assert slow >= 254 * 2e-6
    assert slow - fast >= 254 * 2e-6 - 0.0002  # the delay, whatever the host's own cost
    link.close()
