"""The servo bus through the unmodified ``dynamixel-sdk``, with typed errors.

The SDK reports result codes and never raises; a vanished port surfaces as an
``OSError`` or ``serial.SerialException`` from pyserial and leaves the SDK's
``is_using`` flag set. :class:`SdkBus` turns all of that into the lifecycle's
exceptions (:class:`PortLost`, :class:`ServoSilent`, :class:`ServoRejected`) and
frees the port after any failure, so the next transaction can run.

Reply timeouts follow the SDK's formula (wire time + 2 x USB latency + margin) but
with the configured latency timer instead of the SDK's fixed 16 ms, so a silent
servo costs a few milliseconds of a tick, not 34.
"""

from __future__ import annotations

import os
import termios
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar

import dynamixel_sdk as sdk
import serial

from riderlive.dynamixel.lifecycle import PortLost, RigError, ServoRejected, ServoSilent
from riderlive.dynamixel.tables import ALERT_BIT, BROADCAST_ID, ItemSpec, StatusError

T = TypeVar("T")

_PORT_ERRORS = (OSError, termios.error, serial.SerialException, AttributeError, TypeError)
"""What pyserial raises when the device vanishes (termios.error from a flush on a dead
tty; AttributeError/TypeError: no handle left)."""


_ID, _ERR, _PARAMS = 4, 8, 9
"""Offsets in a status packet: ID, ERR, first parameter."""
_STATUS_BYTES = 11
"""A status packet without parameters: header 4, ID, LEN 2, INST, ERR, CRC 2."""


def _u16(value: int) -> tuple[int, int]:
    return value & 0xFF, value >> 8 & 0xFF


def _instruction(servo_id: int, instruction: int, params: list[int]) -> list[int]:
    """An SDK-style packet buffer (the SDK fills header, stuffing and CRC)."""
    length = len(params) + 3
    return [0, 0, 0, 0, servo_id, *_u16(length), instruction, *params, 0, 0]


class RigPort(sdk.PortHandler):  # type: ignore[misc]
    """A PortHandler whose reply timeout uses the configured adapter latency and counts
    the bytes still queued for the wire.

    A SYNC_WRITE returns as soon as the adapter has the bytes; if the next instruction
    follows at once, its reply can only start after the queued bytes have gone out at
    the baud rate. The SDK's timeout starts at the write call and ignores that queue.
    """

    def __init__(self, port_name: str, latency_ms: float, margin_ms: float) -> None:
        super().__init__(port_name)
        self.latency_ms = latency_ms
        self.margin_ms = margin_ms
        self.wire_free_at = 0.0
        """When the bytes written so far will have left the adapter (SDK clock, ms)."""
        self.last_write: float | None = None
        """perf_counter of the last instruction packet written (what feeds the Bus Watchdog)."""
        self.abort_wait = False
        """Set from another thread (e-stop): a reply being waited for is given up at once."""

    def isPacketTimeout(self) -> bool:
        if self.abort_wait:
            self.packet_timeout = 0
            return True
        return bool(super().isPacketTimeout())

    def writePort(self, packet: list[int]) -> int:
        self.last_write = time.perf_counter()
        now = self.getCurrentTime()
        self.wire_free_at = max(now, self.wire_free_at) + len(packet) * self.tx_time_per_byte
        return int(super().writePort(packet))

    def setPacketTimeout(self, packet_length: int) -> None:
        self.packet_start_time = self.getCurrentTime()
        queued = max(0.0, self.wire_free_at - self.packet_start_time)
        wire = self.tx_time_per_byte * packet_length
        self.packet_timeout = queued + wire + 2.0 * self.latency_ms + self.margin_ms


def usb_latency_timer_ms(port: str) -> int | None:
    """The FTDI latency timer of a ``/dev/ttyUSBn`` port in ms (None if not an FTDI)."""
    name = os.path.basename(os.path.realpath(port))
    path = Path("/sys/bus/usb-serial/devices") / name / "latency_timer"
    try:
        return int(path.read_text().strip())
    except (OSError, ValueError):
        return None


class SdkBus:
    """One serial port, Protocol 2.0; every method is one bus transaction."""

    def __init__(self, port: str, baud: int, latency_ms: float, margin_ms: float) -> None:
        self.port_name = port
        self.baud = baud
        self.port = RigPort(port, latency_ms, margin_ms)
        self.packets = sdk.PacketHandler(2.0)
        self._writers: dict[tuple[int, int], Any] = {}
        self._reader: Any = None
        self._reader_key: tuple[int, int, tuple[int, ...]] | None = None
        self.transactions = 0
        self.stale_replies = 0

    @property
    def is_open(self) -> bool:
        return bool(self.port.is_open)

    def _guard(self, what: str, call: Callable[[], T]) -> T:
        """Run one SDK call; a pyserial failure becomes PortLost; the port is freed."""
        self.transactions += 1
        try:
            return call()
        except _PORT_ERRORS as exc:
            raise PortLost(f"{self.port_name}: {what} failed: {exc}") from exc
        finally:
            self.port.is_using = False

    def open(self) -> None:
        if self.is_open:
            return
        try:
            ok = self.port.openPort() and self.port.setBaudRate(self.baud)
        except _PORT_ERRORS as exc:
            self.port.is_open = False
            raise PortLost(f"cannot open {self.port_name}: {exc}") from exc
        if not ok:
            raise PortLost(f"cannot open {self.port_name} at {self.baud} baud")
        self._writers.clear()
        self._reader = None
        self._reader_key = None

    def close(self) -> None:
        """Close the port, ignoring a handle that is already gone."""
        try:
            if self.port.ser is not None:
                self.port.ser.close()
        except _PORT_ERRORS:
            pass
        self.port.is_open = False
        self.port.is_using = False

    def _check(self, servo_id: int, what: str, result: int, error: int) -> None:
        if result == sdk.COMM_TX_FAIL:
            raise PortLost(f"{self.port_name}: could not send {what} to servo {servo_id}")
        if result != sdk.COMM_SUCCESS:
            raise ServoSilent(servo_id, f"{what}: {self.packets.getTxRxResult(result)}")
        if error & ~ALERT_BIT:
            raise ServoRejected(servo_id, what, StatusError(error & ~ALERT_BIT).name.lower())

    def _transact(self, what: str, servo_id: int, packet: list[int], reply_params: int) -> bytes:
        """Send one instruction packet; return the params of the servo's status reply.

        A reply of the wrong length or from another id is a late answer to an earlier
        instruction (after a timeout): it is skipped, counted, and the wait goes on.
        """

        def run() -> tuple[list[int], int, int]:
            result = self.packets.txPacket(self.port, packet)
            if result != sdk.COMM_SUCCESS:
                return [], result, 0
            self.port.setPacketTimeout(_STATUS_BYTES + reply_params)
            while True:
                reply, result = self.packets.rxPacket(self.port, False)
                if result != sdk.COMM_SUCCESS:
                    return [], result, 0
                if reply[_ID] == servo_id and len(reply) == _STATUS_BYTES + reply_params:
                    return reply[_PARAMS : _PARAMS + reply_params], result, reply[_ERR]
                self.stale_replies += 1

        params, result, error = self._guard(what, run)
        self._check(servo_id, what, result, error)
        return bytes(params)

    def ping(self, servo_id: int) -> int:
        """The servo's model number."""
        params = self._transact("ping", servo_id, _instruction(servo_id, sdk.INST_PING, []), 3)
        return int.from_bytes(params[0:2], "little")

    def read_raw(self, servo_id: int, address: int, length: int) -> bytes:
        """``length`` bytes of the control table from ``address``."""
        packet = _instruction(servo_id, sdk.INST_READ, [*_u16(address), *_u16(length)])
        return self._transact(f"read {length} bytes at {address}", servo_id, packet, length)

    def read(self, servo_id: int, spec: ItemSpec) -> int:
        """One control-table item, decoded (signed where the table says so)."""
        return int.from_bytes(self.read_raw(servo_id, spec.address, spec.size), "little", signed=spec.signed)

    def write(self, servo_id: int, spec: ItemSpec, value: int) -> None:
        """Write one item and check the servo's status reply."""
        data = list(value.to_bytes(spec.size, "little", signed=value < 0))
        packet = _instruction(servo_id, sdk.INST_WRITE, [*_u16(spec.address), *data])
        self._transact(f"write {spec.item}={value}", servo_id, packet, 0)

    def reboot(self, servo_id: int) -> None:
        self._transact("reboot", servo_id, _instruction(servo_id, sdk.INST_REBOOT, []), 0)

    def broadcast_write(self, spec: ItemSpec, value: int) -> None:
        """One WRITE to the broadcast ID: every servo on the bus obeys, none replies."""
        data = list(value.to_bytes(spec.size, "little", signed=value < 0))
        packet = _instruction(BROADCAST_ID, sdk.INST_WRITE, [*_u16(spec.address), *data])
        result = self._guard(f"broadcast write {spec.item}", lambda: self.packets.txPacket(self.port, packet))
        if result != sdk.COMM_SUCCESS:
            raise PortLost(f"{self.port_name}: could not send broadcast write {spec.item}")

    def sync_write(self, spec: ItemSpec, values: Mapping[int, int]) -> None:
        """One SYNC_WRITE of ``spec`` to every id in ``values`` (no replies: feeds no check)."""
        key = (spec.address, spec.size)
        writer = self._writers.get(key)
        if writer is None:
            writer = self._writers[key] = sdk.GroupSyncWrite(self.port, self.packets, spec.address, spec.size)
        for servo_id, value in values.items():
            raw = list(value.to_bytes(spec.size, "little", signed=value < 0))
            if not writer.changeParam(servo_id, raw):
                writer.addParam(servo_id, raw)
        for servo_id in [i for i in writer.data_dict if i not in values]:
            writer.removeParam(servo_id)
        result = self._guard(f"sync write {spec.item}", writer.txPacket)
        if result == sdk.COMM_TX_FAIL:
            raise PortLost(f"{self.port_name}: could not send sync write {spec.item}")
        if result != sdk.COMM_SUCCESS:
            raise RigError(f"sync write {spec.item}: {self.packets.getTxRxResult(result)}")

    def read_block(self, address: int, length: int, ids: Sequence[int], fast: bool) -> dict[int, tuple[int, bytes]]:
        """SYNC_READ (or FAST_SYNC_READ) of ``length`` bytes at ``address`` from ``ids``.

        Returns id -> (status ERR byte, data). Plain Sync Read names the first servo
        that did not answer (ServoSilent with its id and the answers before it in
        ``partial``); Fast Sync Read cannot, and raises ServoSilent without an id.
        """
        key = (address, length, tuple(ids))
        if self._reader_key != key:
            self._reader = sdk.GroupSyncRead(self.port, self.packets, address, length)
            for servo_id in ids:
                self._reader.addParam(servo_id)
            self._reader_key = key
        reader = self._reader
        if fast:
            return self._guard("fast sync read", lambda: self._fast_read(reader, length, ids))
        return self._guard("sync read", lambda: self._plain_read(reader, length, ids))

    def _plain_read(self, reader: Any, length: int, ids: Sequence[int]) -> dict[int, tuple[int, bytes]]:
        result = reader.txPacket()
        if result != sdk.COMM_SUCCESS:
            self._check(ids[0], "sync read", result, 0)
        out: dict[int, tuple[int, bytes]] = {}
        for servo_id in ids:
            data, result, error = self.packets.readRx(self.port, servo_id, length)
            if result != sdk.COMM_SUCCESS:
                raise ServoSilent(servo_id, f"sync read: {self.packets.getTxRxResult(result)}", out)
            out[servo_id] = (int(error), bytes(data))
        return out

    def _fast_read(self, reader: Any, length: int, ids: Sequence[int]) -> dict[int, tuple[int, bytes]]:
        result = reader.fastSyncReadTxPacket()
        if result != sdk.COMM_SUCCESS:
            self._check(ids[0], "fast sync read", result, 0)
        chunk = length + 4  # ERR, ID, data, CRC
        raw, result, _ = self.packets.fastSyncReadRx(self.port, BROADCAST_ID, chunk * len(ids))
        if result != sdk.COMM_SUCCESS:
            raise ServoSilent(None, f"fast sync read: {self.packets.getTxRxResult(result)}")
        raw = bytes(raw)
        out: dict[int, tuple[int, bytes]] = {}
        for start in range(0, len(raw) - chunk + 1, chunk):
            out[raw[start + 1]] = (raw[start], raw[start + 2 : start + 2 + length])
        missing = [i for i in ids if i not in out]
        if missing:
            raise ServoSilent(missing[0], "fast sync read: no data", out)
        return out
