"""An emulated Dynamixel bus on a pseudo-terminal, spoken to by the unmodified SDK.

    with EmulatedBus([ServoSetup(1, "XL430-W250"), ServoSetup(2, "XM430-W350")]) as bus:
        port = dynamixel_sdk.PortHandler(bus.port)   # the pty's slave path, e.g. /dev/pts/7
        ...

A background thread reads instruction packets from the pty master, runs them against
:class:`~riderlive.dynamixel.emulator.servo.EmulatedServo` register memories and writes
the status packets back. With ``wire_timing`` every packet occupies the bus for its
bytes x 10 / baud, and every reply waits for the servo's Return Delay Time, so rates
measured on the emulator are those of a real half-duplex bus at that baud (the host's
USB latency is not emulated). Without it replies are immediate.

Replies of several servos (broadcast PING, SYNC_READ, BULK_READ) go out in ID order
(PING) or request order, one after another; a Fast Sync/Bulk Read reply is one packet
built in turn by each servo, so a servo missing from the chain truncates it.
"""

from __future__ import annotations

import contextlib
import logging
import os
import select
import threading
import time
import tty
from collections import Counter, deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from types import TracebackType

from riderlive.dynamixel.emulator.faults import REPLY_FAULTS, FaultKind, FaultSpec, ServoFaults, corrupt
from riderlive.dynamixel.emulator.instructions import Reply, dispatch
from riderlive.dynamixel.emulator.protocol import (
    CrcError,
    Garbage,
    PacketReader,
    ProtocolError,
    decode_instruction,
    encode_status,
)
from riderlive.dynamixel.emulator.servo import EmulatedServo, ServoSetup
from riderlive.dynamixel.tables import BROADCAST_ID, HardwareError, Instruction, Item, StatusError

log = logging.getLogger(__name__)

DEFAULT_BAUD = 1_000_000
POLL_S = 0.005
"""How often the bus thread wakes when idle (model and watchdog upkeep), s."""
PACKET_GAP_S = 0.010
"""A partial packet older than this is discarded (the e-manual's 1.5 ms gap, relaxed
for a loaded OS scheduler)."""
__all__ = ["DEFAULT_BAUD", "BusStats", "EmulatedBus", "EmulatedServo", "PortClosedError", "ServoSetup"]


class PortClosedError(RuntimeError):
    """The emulated port was closed (fault injection or stop)."""


@dataclass
class BusStats:
    """What the emulator saw and did, for tests and the CLI's summary."""

    packets: int = 0
    instructions: Counter[str] = field(default_factory=Counter)
    replies: int = 0
    bytes_in: int = 0
    bytes_out: int = 0
    crc_errors: int = 0
    malformed: int = 0
    garbage_bytes: int = 0
    dropped_replies: int = 0
    corrupted_replies: int = 0
    lagged_replies: int = 0
    internal_errors: int = 0
    handling_cpu_s: float = 0.0
    """CPU time the bus thread spent handling packets (not waiting for the wire), s."""


class EmulatedBus:
    """Servos behind a pseudo-terminal. Start with :meth:`start` or ``with``."""

    def __init__(
        self,
        servos: Iterable[ServoSetup],
        *,
        baud: int = DEFAULT_BAUD,
        wire_timing: bool = False,
        reboot_time_s: float = 0.0,
        clock: Callable[[], float] = time.perf_counter,
    ) -> None:
        self.baud = baud
        self.wire_timing = wire_timing
        self.reboot_time_s = reboot_time_s
        self.clock = clock
        self.lock = threading.RLock()
        now = clock()
        self.servos: list[EmulatedServo] = [EmulatedServo(setup, baud, now) for setup in servos]
        ids = [servo.id for servo in self.servos]
        if len(set(ids)) != len(ids):
            raise ValueError(f"duplicate servo ids in {ids}")
        self._faults: dict[int, ServoFaults] = {id(servo): ServoFaults() for servo in self.servos}
        self.stats = BusStats()
        self.received: deque[bytes] = deque(maxlen=1024)
        """The last instruction packets received, raw (for byte-exact assertions)."""
        self.arrivals: deque[tuple[float, bytes]] = deque(maxlen=1024)
        """(clock time its last byte arrived on the emulated wire, raw packet) of the same."""
        self.port = ""
        self._master = self._slave = -1
        self._reader = PacketReader()
        self._thread: threading.Thread | None = None
        self._running = False
        self._bus_free_at = 0.0
        self._last_byte = 0.0
        self._last_upkeep = now
        self.closed = False

    # -- lifecycle ---------------------------------------------------------------------

    def start(self) -> EmulatedBus:
        """Open the pseudo-terminal and start answering; ``self.port`` is its path."""
        if self._thread is not None:
            return self
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.port = os.ttyname(self._slave)
        self._running = True
        self._thread = threading.Thread(target=self._run, name=f"servo-emu {self.port}", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread and close the pseudo-terminal (the port vanishes)."""
        self._running = False
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
        self._thread = None
        for fd in (self._master, self._slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = -1
        self.closed = True

    close_port = stop
    """Fault injection: the adapter is unplugged; the host's next read/write fails."""

    def __enter__(self) -> EmulatedBus:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    # -- test API ----------------------------------------------------------------------

    def settle(self, timeout: float = 1.0) -> None:
        """Wait until every byte the host has written so far has been handled."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self.lock:
                if self._master < 0:
                    return
                readable, _, _ = select.select([self._master], [], [], 0)
                if not readable and not self._reader.pending:
                    return
            time.sleep(0.0005)
        raise TimeoutError(f"the emulated bus did not settle within {timeout} s")

    def servo(self, servo_id: int) -> EmulatedServo:
        """The servo whose ID register is ``servo_id`` now (KeyError if none). Hold ``lock``."""
        for servo in self.servos:
            if servo.id == servo_id:
                return servo
        raise KeyError(f"no emulated servo with id {servo_id}")

    def read_item(self, servo_id: int, item: Item) -> int:
        """A register value as the servo would report it now."""
        with self.lock:
            servo = self.servo(servo_id)
            servo.advance(self.clock())
            return servo.get(item)

    def write_item(self, servo_id: int, item: Item, value: int) -> None:
        """Set a register directly, bypassing access rules (test setup)."""
        with self.lock:
            self.servo(servo_id).set(item, value)

    def position(self, servo_id: int) -> float:
        """Where the horn physically is, pulses (without the homing offset)."""
        with self.lock:
            servo = self.servo(servo_id)
            servo.advance(self.clock())
            return servo.state.position

    def apply(self, fault: FaultSpec) -> None:
        """Inject ``fault`` now (``fault.at_s`` is the CLI's business)."""
        if fault.kind is FaultKind.CLOSE:
            self.close_port()
            return
        with self.lock:
            targets = self.servos if fault.servo_id is None else [self.servo(fault.servo_id)]
            for servo in targets:
                faults = self._faults[id(servo)]
                servo.advance(self.clock())
                if fault.kind in REPLY_FAULTS:
                    faults.set_reply_fault(fault)
                elif fault.kind is FaultKind.VANISH:
                    faults.vanished = True
                elif fault.kind is FaultKind.REAPPEAR:
                    faults.vanished = False
                elif fault.kind is FaultKind.OVERHEAT:
                    servo.heat_to(servo.get(Item.TEMPERATURE_LIMIT) + 1.0)
                elif fault.kind is FaultKind.OVERLOAD:
                    servo.raise_hardware_error(HardwareError.OVERLOAD)
                elif fault.kind is FaultKind.VOLTAGE:
                    low = servo.get(Item.MIN_VOLTAGE_LIMIT) / 10.0
                    servo.set_supply(low - 1.0 if fault.volts is None else fault.volts)
                elif fault.kind is FaultKind.CLEAR:
                    faults.drop = faults.corrupt = None

    # -- the bus thread ----------------------------------------------------------------

    def _run(self) -> None:
        while self._running:
            try:
                ready, _, _ = select.select([self._master], [], [], POLL_S)
            except (OSError, ValueError):
                break
            now = self.clock()
            if ready:
                with self.lock:  # held from read to reply, so settle() sees a consistent bus
                    try:
                        data = os.read(self._master, 4096)
                    except BlockingIOError:
                        data = b""
                    except OSError:
                        data = b""
                    if data:
                        self._on_bytes(data, now)
            elif self._reader.pending and now - self._last_byte > PACKET_GAP_S:
                self.stats.garbage_bytes += len(self._reader.reset())
            if now - self._last_upkeep > 2 * POLL_S:
                self._last_upkeep = now
                with self.lock:
                    for servo in self.servos:
                        servo.advance(now)

    def _on_bytes(self, data: bytes, now: float) -> None:
        self._last_byte = now
        self.stats.bytes_in += len(data)
        self._reader.feed(data)
        for item in self._reader.packets():
            if isinstance(item, Garbage):
                self.stats.garbage_bytes += len(item.data)
                continue
            started = time.thread_time()
            try:
                self._handle(item, now)
            except Exception:  # an emulator bug must not kill the bus
                self.stats.internal_errors += 1
                log.exception("servo-emu: failed on packet %s", item.hex(" "))
            self.stats.handling_cpu_s += time.thread_time() - started

    def _active(self, now: float) -> dict[int, EmulatedServo]:
        """Servos that hear the bus now: present, at the bus baud, not rebooting."""
        return {
            servo.id: servo
            for servo in self.servos
            if not self._faults[id(servo)].vanished and servo.listens_at(self.baud) and now >= servo.deaf_until
        }

    def _handle(self, raw: bytes, arrived: float) -> None:
        with self.lock:
            self.received.append(raw)
            self.stats.packets += 1
            now = arrived
            if self.wire_timing:  # the instruction's last byte arrives after its wire time;
                # the servos act at that moment, but only replies wait for the clock
                now = max(arrived, self._bus_free_at) + len(raw) * 10 / self.baud
                self._bus_free_at = now
            self.arrivals.append((now, raw))
            active = self._active(now)
            try:
                packet = decode_instruction(raw)
            except CrcError as exc:
                self.stats.crc_errors += 1
                servo = active.get(exc.packet_id)
                if servo is not None and servo.get(Item.STATUS_RETURN_LEVEL) == 2:
                    self._transmit([Reply(servo, encode_status(servo.id, servo.status_error(StatusError.CRC)))], now)
                return
            except ProtocolError:
                self.stats.malformed += 1
                return
            known = packet.instruction in Instruction._value2member_map_
            name = Instruction(packet.instruction).name if known else hex(packet.instruction)
            self.stats.instructions[name] += 1
            listeners = (
                list(active.values())
                if packet.id == BROADCAST_ID
                else [active[packet.id]]
                if packet.id in active
                else []
            )
            for servo in listeners:
                servo.feed_watchdog(now)
            chunks = dispatch(packet, active, now, self.reboot_time_s) if listeners else []
            self._transmit(chunks, now)

    def _transmit(self, chunks: Sequence[Reply], start: float) -> None:
        """Send the replies, applying reply faults; with wire timing, each at the moment its
        last byte would have left the servo. Bytes due together go out in one write (a
        write per chunk would wake the host once per servo)."""
        t = start
        batch = bytearray()
        for chunk in chunks:
            faults = self._faults[id(chunk.servo)]
            if faults.drop is not None and faults.drop.fires():
                self.stats.dropped_replies += 1
                if chunk.chained:
                    break
                continue
            data = chunk.data
            if faults.corrupt is not None and faults.corrupt.fires():
                self.stats.corrupted_replies += 1
                data = corrupt(data)
            if faults.lag is not None and faults.lag.fires():
                self.stats.lagged_replies += 1
                self._flush(batch)
                self._dribble(data, faults.lag_s)
                t = max(t, self.clock())
                continue
            delay = chunk.servo.return_delay_s if chunk.waits_return_delay else 0.0
            if self.wire_timing:
                t += delay + len(data) * 10 / self.baud
                if not chunk.chained:  # a fast-read chain is useless to the host until complete
                    self._flush(batch)
                    self._sleep_until(t)
            elif delay:  # Return Delay Time is honoured without wire timing too
                self._flush(batch)
                t += delay
                self._sleep_until(t)
            batch += data
            self.stats.replies += 1
        if self.wire_timing:
            self._sleep_until(t)
        self._flush(batch)
        self._bus_free_at = t

    def _flush(self, batch: bytearray) -> None:
        if not batch:
            return
        try:
            os.write(self._master, batch)
            self.stats.bytes_out += len(batch)
        except OSError:
            self.stats.dropped_replies += 1
        batch.clear()

    def _dribble(self, data: bytes, length_s: float) -> None:
        """``data`` a byte at a time, evenly over ``length_s`` (the ``lag`` fault)."""
        start = time.perf_counter()
        for i, byte in enumerate(data):
            end = start + length_s * (i + 1) / len(data)
            remaining = end - time.perf_counter()
            if remaining > 0:
                time.sleep(remaining)
            self._flush(bytearray((byte,)))

    def _sleep_until(self, deadline: float) -> None:
        """Sleep, then spin the last millisecond: OS sleeps overshoot, and a yield on a busy
        machine can give the core away for a whole time slice."""
        remaining = deadline - self.clock()
        if remaining <= 0:
            return
        end = time.perf_counter() + remaining  # real time, whatever clock the bus runs on
        if remaining > 0.0015:
            time.sleep(remaining - 0.001)
        while time.perf_counter() < end:
            pass
