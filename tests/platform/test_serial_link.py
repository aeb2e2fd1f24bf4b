"""The serial transport: handshake, commands and telemetry against the firmware's host build
on a pty; a wrong version, silence, a vanished port and bad frames from a scripted device."""

from __future__ import annotations

import pytest

from riderlive.platform import link, link_vocab
from riderlive.platform.firmware_host import FirmwareHost
from riderlive.platform.link_vocab import LinkState, Reason
from riderlive.platform.serial_link import (
    CommandRefused,
    Health,
    NoAnswer,
    PortLost,
    SerialPlatformLink,
    VersionMismatch,
)
from tests.platform.fake_device import FakeDevice, reply_hello, telemetry


def test_handshake_commands_and_telemetry_with_the_firmware() -> None:
    with FirmwareHost("platform6") as firmware, SerialPlatformLink(firmware.port) as port:
        hello = port.open()
        assert hello.device == "platform6" and hello.actuators == 6 and hello.profile == link_vocab.Profile.PLATFORM6
        assert hello.period_us == 4000 and hello.heartbeat_ms == 200
        assert port.heartbeat_s == pytest.approx(0.05)
        with pytest.raises(CommandRefused) as refused:
            port.command(link.Arm("platform"))  # not its name
        assert refused.value.reason is Reason.WRONG_DEVICE
        assert "wrong_device" in str(refused.value) and "disarmed" in str(refused.value)
        port.send_targets([7000] * 6)  # not armed: refused by the device, counted there
        seen = port.wait_telemetry(lambda t: t.counter("refused") >= 2, 2.0)
        assert LinkState(seen.state) is LinkState.DISARMED and seen.last_reason == Reason.NOT_ARMED
        assert seen.commanded == (500,) * 6 and port.state is LinkState.DISARMED
        assert port.health is Health.OK and port.counters["rx_ok"] >= 3
        assert sum(v for k, v in port.counters.items() if k.startswith("rx_") and k not in ("rx_ok", "rx_gap")) == 0
        port.close()
        assert port.health is Health.CLOSED and port.state is LinkState.DISCONNECTED
        assert firmware.status()["state"] == "disarmed"


def test_a_device_with_another_version_is_refused_clearly() -> None:
    device = FakeDevice(reply_hello(version=2))
    port = SerialPlatformLink(device.port)
    with pytest.raises(VersionMismatch, match=r"speaks platform link v2, this riderlive speaks v1") as caught:
        port.open(timeout_s=2.0)
    assert caught.value.device_version == 2
    assert port.counters["rx_version"] == 1 and port.state is LinkState.DISCONNECTED
    assert [f.message for f in device.frames] == [link.Hello()]  # nothing but HELLO was sent
    device.vanish()


def test_no_answer_and_a_missing_port() -> None:
    device = FakeDevice()  # never answers
    with pytest.raises(NoAnswer, match="no HELLO_REPLY"):
        SerialPlatformLink(device.port).open(timeout_s=0.2)
    device.vanish()
    with pytest.raises(PortLost):
        SerialPlatformLink("/dev/riderlive-no-such-port").open()


def test_bad_frames_from_the_device_are_dropped_counted_never_used() -> None:
    device = FakeDevice(reply_hello(seq=10))
    port = SerialPlatformLink(device.port)
    port.open(timeout_s=2.0)
    good = link.encode(telemetry(1111), 11)
    flipped = bytearray(link.encode(telemetry(6666), 12))
    flipped[5] ^= 0x01
    device.write(
        good
        + good  # a repeat
        + link.encode(telemetry(2222), 9)  # older
        + bytes(flipped)  # a CRC error
        + link.encode(telemetry(3333), 12)[:20]
        + b"\x00"  # truncated: its last COBS code points past the end
        + link.encode(telemetry(4444), 13, version=2)  # another version
        + b"\x55" * 300
        + b"\x00"  # an over-long run
        + link.encode(link.Heartbeat(), 14)  # a host frame: not for the host
    )
    port.wait_telemetry(lambda t: True, 2.0)
    for _ in range(50):  # let every byte arrive
        port._receive(0.01)
    assert port.telemetry is not None and port.telemetry.commanded[0] == 1111
    c = port.counters
    counts = (c["rx_stale"], c["rx_crc"], c["rx_cobs"], c["rx_version"], c["rx_oversize"], c["rx_type"])
    assert counts == (2, 1, 1, 1, 1, 1)
    device.write(link.encode(telemetry(5555), 15))
    assert port.wait_telemetry(lambda t: t.commanded[0] == 5555, 2.0).measured[0] == 5555
    assert port.counters["rx_gap"] == 3  # 12, 13 and 14 never counted as received
    port.close()
    device.vanish()


def test_telemetry_of_the_session_before_the_reply_is_not_trusted() -> None:
    """A reconnect: the device's telemetry sent before it read our HELLO (the session before,
    moving) arrives ahead of its HELLO_REPLY; it is dropped as stale, and the link's telemetry
    is the new session's. (A loaded run read such a frame into the new session.)"""

    def on_frame(device: FakeDevice, frame: link.Frame) -> None:
        if isinstance(frame.message, link.Hello):
            reply = link.HelloReply((9, 9), link_vocab.Profile.SERVO8, 8, 4000, 200, "fake")
            device.write(link.encode(telemetry(1234), 40) + link.encode(reply, 10))

    device = FakeDevice(on_frame)
    port = SerialPlatformLink(device.port)
    port.open(timeout_s=2.0)
    assert port.telemetry is None and port.counters["rx_stale"] == 1 and port.counters["rx_ok"] == 1
    device.write(link.encode(telemetry(0, link_vocab.LinkState.PARKED), 11))
    parked = port.wait_telemetry(lambda t: True, 2.0)
    assert LinkState(parked.state) is LinkState.PARKED and parked.commanded == (0,) * 8
    port.close()
    device.vanish()


def test_a_silent_device_then_a_vanished_port() -> None:
    device = FakeDevice(reply_hello())
    clock = [100.0]
    port = SerialPlatformLink(device.port, silence_s=0.25, heartbeat_s=10.0, clock=lambda: clock[0])
    port.open(timeout_s=2.0)
    port.service()
    assert port.health is Health.OK
    clock[0] += 0.3
    port.service()
    assert port.health is Health.SILENT and port.counters["silences"] == 1
    device.write(link.encode(telemetry(10), 11))
    port.wait_telemetry(lambda t: True, 2.0)
    assert port.health is Health.OK
    device.vanish()
    with pytest.raises(PortLost):
        for _ in range(100):
            port._receive(0.01)
    assert port.health is Health.LOST and port.state is LinkState.DISCONNECTED
    assert port.counters["port_lost"] == 1
    with pytest.raises(PortLost):
        port.send_targets([0] * 8)


def test_reconnecting_parks_a_moving_device_and_never_rearms() -> None:
    with FirmwareHost("servo8") as firmware, SerialPlatformLink(firmware.port) as port:
        port.open()
        # the longest dead-man: a test process descheduled for 200 ms must not trip it here
        port.command(link.Config(link_vocab.ConfigKey.HEARTBEAT_TIMEOUT_MS, 0, 1000))
        port.command(link.Arm("servo8"))
        flood = 0
        while port.telemetry is None or LinkState(port.telemetry.state) is not LinkState.RUNNING:
            port.send_targets([1500] * 8)  # as fast as Python goes: the control step must still run
            port.service()
            flood += 1
            assert flood < 200_000, "the flood starved the firmware's control step"
        port.close()
        hello = port.open()  # the same process reconnecting, as after a glitch
        assert port.telemetry is None and hello.device == "servo8"
        parked = port.wait_telemetry(lambda t: LinkState(t.state) is LinkState.PARKED, 5.0)
        assert parked.commanded == (0,) * 8 and parked.faults == 0
        port.send_targets([1500] * 8)
        refused = port.wait_telemetry(lambda t: t.last_reason == Reason.NOT_ARMED, 2.0)
        assert LinkState(refused.state) is LinkState.PARKED
        firmware.wait_event(lambda e: e["event"] == "state" and e["to"] == "parked", 5.0)
        assert firmware.states() == ["soft_start", "running", "parking", "parked"]
