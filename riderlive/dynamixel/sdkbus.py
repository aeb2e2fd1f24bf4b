"""The servo bus through the unmodified ``dynamixel-sdk``, with typed errors.

The SDK reports result codes and never raises; a vanished port surfaces as an
``OSError`` or ``serial.SerialException`` from pyserial and leaves the SDK's
``is_using`` flag set. :class:`SdkBus` turns all of that into the lifecycle's
exceptions (:class:`PortLost`, :class:`PortBusy`, :class:`NoReply`, :class:`Rejected`,
:class:`StopRequested`) and frees the port after any failure.

Reply timeouts: the expected time (the bytes still queued for the wire, the reply's
wire time, twice the adapter's latency timer) plus an allowance measured from the
replies themselves (:class:`~riderlive.devices.budget.ReplyTimer`, one per kind of
transaction: the host's real scheduling delays, never below ``timeout_margin_ms``,
backing off after a miss), on a monotonic clock (the SDK's own uses wall time, which
jumps). After a reply that failed, the line is drained of its late remainder before
the next request, so a late reply never corrupts the next one.

The port is opened exclusively (``flock``): the tick and the guardian never write
the bus at the same time, and a process that dies releases it with its file.
While a reply is awaited, a pending e-stop request gives the wait up at once.

In the tick, each wait for bytes is declared with its deadline, cleared when the transaction
ends (``RigPort.io_wait``, ``devices/iowait.py``): a bounded reply wait is not a hang.
"""

from __future__ import annotations

import dataclasses
import os
import select
import termios
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, NoReturn, TypeVar

import dynamixel_sdk as sdk
import serial

from riderlive.devices.budget import ReplyTimer
from riderlive.devices.iowait import IoWait
from riderlive.devices.latch import StopView
from riderlive.devices.lifecycle import DeviceError, NoReply, PortBusy, PortLost, Rejected, StopRequested
from riderlive.dynamixel.tables import ALERT_BIT, BROADCAST_ID, ItemSpec, StatusError

T = TypeVar("T")
READ_WAIT_S = 0.0002
"""While a reply is awaited and nothing has arrived: how long one read waits for the port
(s; it returns as soon as bytes come). Bounds how late an e-stop request ends the wait."""

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
    """A PortHandler with measured reply timeouts, a monotonic clock, an exclusive open,
    and a wait that an e-stop request cuts short.

    A SYNC_WRITE returns as soon as the adapter has the bytes; if the next instruction
    follows at once, its reply can only start after the queued bytes have gone out at
    the baud rate, so the timeout counts them too.
    """

    is_open: bool
    packet_timeout: float

    def __init__(self, port_name: str, latency_ms: float, timer: ReplyTimer) -> None:
        super().__init__(port_name)
        self.latency_ms = latency_ms
        self.timer = timer
        self.wire_free_at = 0.0
        """When the bytes written so far will have left the adapter (ms, this port's clock)."""
        self.expected_ms = 0.0
        self.last_write: float | None = None
        """perf_counter of the last instruction packet written (what feeds the Bus Watchdog)."""
        self.stops: StopView | None = None
        self.aborted = False
        """The last wait was given up for an e-stop request."""
        self.io_wait: IoWait | None = None
        """Where each wait's deadline is declared (the tick's safety board; None: nowhere)."""

    def getCurrentTime(self) -> float:
        return time.perf_counter() * 1000.0

    def setupPort(self, cflag_baud: int) -> bool:
        if self.is_open:
            self.closePort()
        self.ser = serial.Serial(port=self.port_name, baudrate=self.baudrate, timeout=0, exclusive=True)
        self.is_open = True
        self.ser.reset_input_buffer()
        self.tx_time_per_byte = 10_000.0 / self.baudrate
        return True

    def readPort(self, length: int) -> bytes:
        """What has arrived (at most ``length`` bytes). With nothing there, wait up to
        :data:`READ_WAIT_S` for the port to become readable instead of returning at once:
        the SDK calls this in a loop until its timeout, and a real-time process spinning
        on it can starve the kernel's tty worker (a normal-priority thread) that must
        deliver the very reply it waits for, on a USB adapter as on the emulator's pty."""
        data: bytes = self.ser.read(length)
        if not data:
            select.select([self.ser.fileno()], [], [], READ_WAIT_S)
        return data

    def isPacketTimeout(self) -> bool:
        if self.stops is not None and self.stops.pending:
            self.aborted = True
            self.packet_timeout = 0.0
            return True
        return bool(super().isPacketTimeout())

    def writePort(self, packet: list[int]) -> int:
        begun = time.perf_counter()  # before the check: a write stamped after a request's time is refused
        if self.stops is not None:  # inside the latch's gate: a request recorded since its entry
            self.stops.check_write()  # stops this write before its first byte (the goal at the write)
        self.last_write = begun
        now = self.getCurrentTime()
        self.wire_free_at = max(now, self.wire_free_at) + len(packet) * self.tx_time_per_byte
        return int(super().writePort(packet))

    def setPacketTimeout(self, packet_length: int) -> None:
        self.packet_start_time = self.getCurrentTime()
        queued = max(0.0, self.wire_free_at - self.packet_start_time)
        self.expected_ms = queued + self.tx_time_per_byte * packet_length + 2.0 * self.latency_ms
        self.packet_timeout = self.timer.timeout_ms(self.expected_ms)
        self._declare_wait(self.packet_start_time + self.packet_timeout)

    def setPacketTimeoutMillis(self, msec: float) -> None:
        super().setPacketTimeoutMillis(msec)
        self._declare_wait(self.packet_start_time + msec)

    def _declare_wait(self, deadline_ms: float) -> None:  # a wait for bytes begins (ms, getCurrentTime's)
        if self.io_wait is not None:
            self.io_wait.until(deadline_ms / 1000.0)

    def replied(self) -> None:
        """A reply arrived: teach the timer how late it was."""
        self.timer.observe(self.getCurrentTime() - self.packet_start_time - self.expected_ms)

    def drain(self, quiet_ms: float, max_ms: float) -> int:
        """Read and drop bytes until the line has been quiet for ``quiet_ms`` (at most
        ``max_ms``): the late remainder of a reply given up on, which would otherwise
        corrupt the next one. Returns the bytes dropped."""
        start = last = self.getCurrentTime()
        dropped = 0
        self._declare_wait(start + max_ms)
        while (now := self.getCurrentTime()) - last < quiet_ms and now - start < max_ms:
            waiting = self.ser.in_waiting
            if waiting:
                dropped += len(self.ser.read(waiting))
                last = self.getCurrentTime()
            else:
                time.sleep(0.0001)
        return dropped


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

    def __init__(self, port: str, baud: int, latency_ms: float, timer: ReplyTimer) -> None:
        self.port_name = port
        self.baud = baud
        self.port = RigPort(port, latency_ms, timer)
        self.timers = {kind: dataclasses.replace(timer) for kind in ("unicast", "sync read", "fast sync read")}
        """One reply timer per kind of transaction: a 24-servo read is not a ping."""
        self.packets = sdk.PacketHandler(2.0)
        self._writers: dict[tuple[int, int], Any] = {}
        self._readers: dict[tuple[int, int, tuple[int, ...]], Any] = {}
        self.transactions = 0
        self.stale_replies = 0
        self.stale_bytes = 0
        self.timeouts = 0
        self._unsettled = False

    @property
    def is_open(self) -> bool:
        return bool(self.port.is_open)

    @property
    def unsettled(self) -> bool:
        """A reply was given up on: its late remainder may still be on the line."""
        return self._unsettled

    def _guard(self, what: str, call: Callable[[], T], kind: str = "unicast", settle: bool = True) -> T:
        """Run one SDK call; a pyserial failure becomes PortLost; the port is freed. After
        a reply that failed, the line is first drained of its late remainder (unless not
        ``settle``: an e-stop's first write goes out at once)."""
        self.transactions += 1
        self.port.timer = self.timers[kind]
        try:
            if self._unsettled and settle:
                self._unsettled = False
                quiet = 2.0 * self.port.latency_ms + 1.0
                self.stale_bytes += self.port.drain(quiet, quiet + self.port.timer.allowance_ms())
            return call()
        except _PORT_ERRORS as exc:
            raise PortLost(f"{self.port_name}: {what} failed: {exc}") from exc
        finally:
            self.port.is_using = False
            if self.port.io_wait is not None:
                self.port.io_wait.done()
            if self.port.aborted:
                self.port.aborted = False
                raise StopRequested(f"{what}: given up for an e-stop")

    def open(self) -> None:
        if self.is_open:
            return
        try:
            ok = self.port.openPort() and self.port.setBaudRate(self.baud)
        except serial.SerialException as exc:
            self.port.is_open = False
            if "exclusively lock" in str(exc):
                raise PortBusy(f"{self.port_name} is held by another process") from exc
            raise PortLost(f"cannot open {self.port_name}: {exc}") from exc
        except _PORT_ERRORS as exc:
            self.port.is_open = False
            raise PortLost(f"cannot open {self.port_name}: {exc}") from exc
        if not ok:
            raise PortLost(f"cannot open {self.port_name} at {self.baud} baud")
        self._writers.clear()
        self._readers.clear()

    def close(self) -> None:
        """Close the port (releasing its lock), ignoring a handle that is already gone."""
        try:
            if self.port.ser is not None:
                self.port.ser.close()
        except _PORT_ERRORS:
            pass
        self.port.is_open = False
        self.port.is_using = False

    def _result(self, servo_id: int | None, what: str, result: int) -> NoReturn:
        """A failed SDK result as the lifecycle's error (timeouts teach the timer)."""
        if result == sdk.COMM_TX_FAIL:
            raise PortLost(f"{self.port_name}: could not send {what}")
        if result == sdk.COMM_RX_TIMEOUT:
            self.timeouts += 1
            self.port.timer.missed()
        self._unsettled = True
        raise NoReply(servo_id, f"{what}: {self.packets.getTxRxResult(result)}")

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
                    self.port.replied()
                    return reply[_PARAMS : _PARAMS + reply_params], result, reply[_ERR]
                self.stale_replies += 1

        params, result, error = self._guard(what, run)
        if result != sdk.COMM_SUCCESS:
            self._result(servo_id, what, result)
        if error & ~ALERT_BIT:
            raise Rejected(servo_id, what, StatusError(error & ~ALERT_BIT).name.lower())
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

    def broadcast_write(self, spec: ItemSpec, value: int, settle: bool = True) -> None:
        """One WRITE to the broadcast ID: every servo on the bus obeys, none replies.

        ``settle=False`` writes at once even if a reply given up on may still be on the
        line (:attr:`unsettled`): on the half-duplex bus the two may collide, so the
        caller writes again with ``settle=True``, which first waits for a quiet line."""
        data = list(value.to_bytes(spec.size, "little", signed=value < 0))
        packet = _instruction(BROADCAST_ID, sdk.INST_WRITE, [*_u16(spec.address), *data])
        send = lambda: self.packets.txPacket(self.port, packet)  # noqa: E731
        result = self._guard(f"broadcast write {spec.item}", send, settle=settle)
        if result != sdk.COMM_SUCCESS:
            raise PortLost(f"{self.port_name}: could not send broadcast write {spec.item}")

    def sync_write(self, spec: ItemSpec, values: Mapping[int, int]) -> None:
        """One SYNC_WRITE of ``spec`` to every id in ``values`` (no replies)."""
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
            raise DeviceError(f"sync write {spec.item}: {self.packets.getTxRxResult(result)}")

    def read_block(self, address: int, length: int, ids: Sequence[int], fast: bool) -> dict[int, tuple[int, bytes]]:
        """SYNC_READ (or FAST_SYNC_READ) of ``length`` bytes at ``address`` from ``ids``.

        Returns id -> (status ERR byte, data). Plain Sync Read names the first servo
        that did not answer (NoReply with its id and the answers before it in
        ``partial``); Fast Sync Read cannot, and raises NoReply without an id.
        """
        key = (address, length, tuple(ids))
        reader = self._readers.get(key)
        if reader is None:
            reader = self._readers[key] = sdk.GroupSyncRead(self.port, self.packets, address, length)
            for servo_id in ids:
                reader.addParam(servo_id)
        if fast:
            return self._guard("fast sync read", lambda: self._fast_read(reader, length, ids), "fast sync read")
        return self._guard("sync read", lambda: self._plain_read(reader, length, ids), "sync read")

    def _plain_read(self, reader: Any, length: int, ids: Sequence[int]) -> dict[int, tuple[int, bytes]]:
        result = reader.txPacket()
        if result != sdk.COMM_SUCCESS:
            self._result(ids[0], "sync read", result)
        out: dict[int, tuple[int, bytes]] = {}
        for servo_id in ids:
            data, result, error = self.packets.readRx(self.port, servo_id, length)
            if result != sdk.COMM_SUCCESS:
                try:
                    self._result(servo_id, "sync read", result)
                except NoReply:
                    raise NoReply(servo_id, f"sync read: {self.packets.getTxRxResult(result)}", out) from None
            out[servo_id] = (int(error), bytes(data))
        self.port.replied()
        return out

    def _fast_read(self, reader: Any, length: int, ids: Sequence[int]) -> dict[int, tuple[int, bytes]]:
        result = reader.fastSyncReadTxPacket()
        if result != sdk.COMM_SUCCESS:
            self._result(ids[0], "fast sync read", result)
        chunk = length + 4  # ERR, ID, data, CRC
        raw, result, _ = self.packets.fastSyncReadRx(self.port, BROADCAST_ID, chunk * len(ids))
        if result != sdk.COMM_SUCCESS:
            self._result(None, "fast sync read", result)
        self.port.replied()
        raw = bytes(raw)
        out: dict[int, tuple[int, bytes]] = {}
        for start in range(0, len(raw) - chunk + 1, chunk):
            out[raw[start + 1]] = (raw[start], raw[start + 2 : start + 2 + length])
        missing = [i for i in ids if i not in out]
        if missing:
            raise NoReply(missing[0], "fast sync read: no data", out)
        return out
