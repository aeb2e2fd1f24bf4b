"""The platform link over a serial port (pyserial): handshake, heartbeat, commands, telemetry.

The codec is :mod:`riderlive.platform.link`; this module owns the port. Single-threaded by
design: the caller (the tick) calls :meth:`SerialPlatformLink.service` every period, which
reads what arrived, sends a heartbeat when nothing else was sent for ``heartbeat_s`` and
notices a silent device. No background thread keeps the dead-man fed: if the caller stops,
the heartbeats stop and the firmware parks by itself (docs/platform-link.md).

    link = SerialPlatformLink("/dev/ttyACM0")
    hello = link.open()                       # VersionMismatch / NoAnswer / PortLost
    link.command(Arm(hello.device))           # CommandRefused if the device says no
    while running:
        link.send_targets(counts)             # one TARGET a tick
        link.service()
    link.command(Park()); link.close()

Every frame from the device is checked (COBS, CRC, version, type, length, sequence);
whatever fails is dropped and counted in :attr:`counters`, never acted on.
"""

from __future__ import annotations

import contextlib
import enum
import select
import time
from collections import Counter
from collections.abc import Callable, Sequence
from typing import Any

import serial

from riderlive.platform.link import (
    COUNTERS,
    Frame,
    Heartbeat,
    Hello,
    HelloReply,
    Message,
    Status,
    Target,
    Telemetry,
    decode,
    encode,
)
from riderlive.platform.link_framing import LINK_VERSION, SEQ_MOD, Deframer, LinkError, SeqWindow, VersionError
from riderlive.platform.link_vocab import FrameType, LinkState, Reason

DEFAULT_BAUD = 250_000
"""Exact on a 16 MHz AVR (the Mega 2560 shim); a pty ignores it."""
MAX_PENDING_STATUSES = 32


class PlatformLinkError(Exception):
    """Base of the transport's errors."""


class PortLost(PlatformLinkError):
    """The serial port could not be opened, or vanished while in use."""


class PortBusy(PlatformLinkError):
    """Another process holds the port (the port is opened exclusively: one writer at a time)."""


class NoAnswer(PlatformLinkError):
    """The device did not answer the handshake or a command in time."""


class VersionMismatch(PlatformLinkError):
    """The device speaks another link version: refused, nothing is sent to it but HELLO."""

    def __init__(self, port: str, device_version: int) -> None:
        self.device_version = device_version
        super().__init__(
            f"{port}: the device speaks platform link v{device_version}, this riderlive speaks "
            f"v{LINK_VERSION}; flash the firmware_proto of this release (docs/platform-link.md, Versioning)"
        )


class CommandRefused(PlatformLinkError):
    """The device answered a command with a reason other than OK."""

    def __init__(self, message: Message, status: Status) -> None:
        self.status = status
        self.reason = Reason(status.result)
        state = LinkState(status.state).label
        super().__init__(f"{message.TYPE.name.lower()} refused: {self.reason.name.lower()} (device {state})")


class Health(enum.Enum):
    """How the link is doing, from this side."""

    CLOSED = "closed"
    OK = "ok"
    SILENT = "silent"  # no valid frame from the device for silence_s
    LOST = "lost"  # the port vanished


class SerialPlatformLink:
    """One device on one serial port; see the module docstring."""

    def __init__(
        self,
        port: str,
        *,
        baud: int = DEFAULT_BAUD,
        heartbeat_s: float | None = None,
        silence_s: float = 0.25,
        clock: Callable[[], float] = time.monotonic,
        corrupt: Callable[[bytes], bytes] | None = None,
    ) -> None:
        """``heartbeat_s``: send a HEARTBEAT when nothing was sent for this long (default: a
        quarter of the device's dead-man timeout). ``corrupt`` rewrites outgoing bytes (tests
        and benches of a noisy line only)."""
        self.port = port
        self.baud = baud
        self.heartbeat_s = heartbeat_s
        self.silence_s = silence_s
        self._clock = clock
        self._corrupt = corrupt
        self._serial: Any = None
        self._deframer = Deframer()
        self._window = SeqWindow()
        self._seq = 0
        self._last_sent = 0.0
        self._last_valid = 0.0
        self._statuses: dict[int, Status] = {}
        self.device: HelloReply | None = None
        self.telemetry: Telemetry | None = None
        self.health = Health.CLOSED
        self.counters: Counter[str] = Counter()
        """This side's counts: rx_ok, rx_<error kind>, rx_stale, rx_gap, tx_frames, silences, port_lost."""

    # --- opening and closing ---

    def open(self, timeout_s: float = 1.0) -> HelloReply:
        """Open the port and shake hands: HELLO, then the device's HELLO_REPLY in our version.

        Also how to reconnect: a HELLO parks a device that was moving (docs/platform-link.md)."""
        try:
            self._serial = serial.Serial(self.port, self.baud, timeout=0, write_timeout=0.5, exclusive=True)
            self._serial.reset_input_buffer()
        except (serial.SerialException, OSError) as exc:
            if "exclusively lock" in str(exc):
                raise PortBusy(f"{self.port} is held by another process") from exc
            self._lost()
            raise PortLost(f"{self.port}: {exc}") from exc
        self.health = Health.OK
        self._window.restart()
        self._deframer = Deframer()
        self._statuses.clear()
        self.device = None
        self.telemetry = None  # nothing from an earlier session is trusted
        self._write(b"\x00")  # ends whatever partial frame the device holds
        self.send(Hello())
        deadline = self._clock() + timeout_s
        while self.device is None:
            left = deadline - self._clock()
            if left <= 0:
                self.close()
                raise NoAnswer(f"{self.port}: no HELLO_REPLY within {timeout_s} s (is firmware_proto running?)")
            self._receive(min(left, 0.02), handshake=True)
        if self.heartbeat_s is None:
            self.heartbeat_s = self.device.heartbeat_ms / 4000.0
        return self.device

    def close(self) -> None:
        """Close the port (the firmware's dead-man parks a moving device)."""
        if self._serial is not None:
            with contextlib.suppress(serial.SerialException, OSError):
                self._serial.close()
        self._serial = None
        if self.health is not Health.LOST:
            self.health = Health.CLOSED

    def __enter__(self) -> SerialPlatformLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def state(self) -> LinkState:
        """The device's lifecycle state as last reported; DISCONNECTED without a port."""
        if self._serial is None or self.health is Health.LOST:
            return LinkState.DISCONNECTED
        if self.device is None:
            return LinkState.CONNECTING
        return LinkState(self.telemetry.state) if self.telemetry else LinkState.CONNECTING

    # --- sending ---

    def send(self, message: Message) -> int:
        """Encode and write one frame; returns its seq."""
        seq = self._seq
        self._seq = (self._seq + 1) % SEQ_MOD
        self._write(encode(message, seq))
        self.counters["tx_frames"] += 1
        return seq

    def send_targets(self, positions: Sequence[int]) -> int:
        """One TARGET frame (counts, one per actuator). The device refuses it unless armed."""
        return self.send(Target(tuple(positions)))

    def command(self, message: Message, timeout_s: float = 0.5, *, check: bool = True) -> Status:
        """Send a command frame and wait for its STATUS; ``CommandRefused`` unless OK (if ``check``)."""
        seq = self.send(message)
        deadline = self._clock() + timeout_s
        while seq not in self._statuses:
            left = deadline - self._clock()
            if left <= 0:
                raise NoAnswer(f"{self.port}: no STATUS for {message.TYPE.name.lower()} within {timeout_s} s")
            self._receive(min(left, 0.02))
            self._heartbeat()
        status = self._statuses.pop(seq)
        if check and status.result != Reason.OK:
            raise CommandRefused(message, status)
        return status

    # --- the periodic call ---

    def service(self) -> None:
        """Read what arrived (never blocks), heartbeat if due, notice silence. ``PortLost``."""
        self._receive(0.0)
        self._heartbeat()

    def wait_telemetry(self, predicate: Callable[[Telemetry], bool], timeout_s: float) -> Telemetry:
        """Service the link until a TELEMETRY satisfies ``predicate``; ``NoAnswer`` on timeout."""
        deadline = self._clock() + timeout_s
        while True:
            if self.telemetry is not None and predicate(self.telemetry):
                return self.telemetry
            left = deadline - self._clock()
            if left <= 0:
                state = self.state.label
                raise NoAnswer(f"{self.port}: telemetry did not reach the expected condition ({state})")
            self._receive(min(left, 0.02))
            self._heartbeat()

    def device_counters(self) -> dict[str, int]:
        """The device's own counters from its last TELEMETRY (empty before one)."""
        return dict(zip(COUNTERS, self.telemetry.counters, strict=True)) if self.telemetry else {}

    # --- internals ---

    def _heartbeat(self) -> None:
        if self.heartbeat_s is not None and self._clock() - self._last_sent >= self.heartbeat_s:
            self.send(Heartbeat())

    def _write(self, data: bytes) -> None:
        if self._serial is None:
            raise PortLost(f"{self.port}: not open")
        try:
            self._serial.write(self._corrupt(data) if self._corrupt else data)
        except (serial.SerialException, OSError) as exc:
            self._lost()
            raise PortLost(f"{self.port}: {exc}") from exc
        self._last_sent = self._clock()

    def _lost(self) -> None:
        if self.health is not Health.LOST:
            self.counters["port_lost"] += 1
        self.health = Health.LOST
        self._serial = None

    def _read(self, wait_s: float) -> bytes:
        if self._serial is None:
            raise PortLost(f"{self.port}: not open")
        try:
            if wait_s > 0:
                select.select([self._serial.fileno()], [], [], wait_s)
            waiting = self._serial.in_waiting
            data: bytes = self._serial.read(waiting) if waiting else b""
            if not waiting and wait_s > 0:
                data = self._serial.read(1)  # readable but empty: raises if the port vanished
        except (serial.SerialException, OSError) as exc:
            self._lost()
            raise PortLost(f"{self.port}: {exc}") from exc
        return data

    def _receive(self, wait_s: float, handshake: bool = False) -> None:
        data = self._read(wait_s)
        for packet in self._deframer.feed(data):
            try:
                frame = decode(packet)
            except VersionError as exc:
                self.counters["rx_version"] += 1
                if handshake:
                    self.close()
                    raise VersionMismatch(self.port, exc.version) from None
                continue
            except LinkError as exc:
                self.counters[f"rx_{exc.kind}"] += 1
                continue
            self._accept(frame)
        self.counters["rx_oversize"] += self._deframer.oversize
        self._deframer.oversize = 0
        now = self._clock()
        if self.device is not None and now - self._last_valid > self.silence_s:
            if self.health is Health.OK:
                self.health = Health.SILENT
                self.counters["silences"] += 1
        elif self.health is Health.SILENT:
            self.health = Health.OK

    def _accept(self, frame: Frame) -> None:
        message = frame.message
        if message.TYPE < FrameType.HELLO_REPLY:
            self.counters["rx_type"] += 1  # a host -> device frame: not for us
            return
        if isinstance(message, HelloReply):
            self._window.restart(frame.seq)  # a session starts at the device's reply
        elif self.device is None:  # before it: the session before, still on the wire
            self.counters["rx_stale"] += 1
            return
        else:
            gap = self._window.check(frame.seq)
            if gap is None:
                self.counters["rx_stale"] += 1
                return
            self.counters["rx_gap"] += gap
        self.counters["rx_ok"] += 1
        self._last_valid = self._clock()
        if isinstance(message, HelloReply):
            self.device = message
        elif isinstance(message, Status):
            self._statuses[message.ack_seq] = message
            if len(self._statuses) > MAX_PENDING_STATUSES:  # answers nobody waited for
                del self._statuses[next(iter(self._statuses))]
        elif isinstance(message, Telemetry):
            self.telemetry = message
