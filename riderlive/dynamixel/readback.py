"""The divided read: what the servos report back, and which of them went silent.

Every ``read_divider`` ticks the driver reads 15 bytes from each servo, Present Position
(132) .. Present Temperature (146), with one Fast Sync Read (a single reply packet
for the whole bus) or, after failures, a plain Sync Read (one reply per servo, so a
silent servo is named). Each servo's status ERR byte comes along; its Alert bit means
"read my Hardware Error Status".

A failed read is repeated on the next tick. A servo is declared silent when it has
missed every read for ``reply_budget_s``; a Fast Sync Read that fails is retried as a
plain one (which names the culprit), and after ``fast_read_fallback_after`` failures
the plain read is used until the next start.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

from riderlive.dynamixel.bringup import hardware_bits
from riderlive.dynamixel.lifecycle import ServoHardwareError, ServoSilent
from riderlive.dynamixel.rig import RigConfig, pulses_to_deg
from riderlive.dynamixel.sdkbus import SdkBus
from riderlive.dynamixel.status import BusCounters
from riderlive.dynamixel.tables import ALERT_BIT, Item, ItemSpec

log = logging.getLogger("riderlive.dynamixel")


class Readback:
    """The read's state (fast or plain, retrying, who is missing) and the latest values."""

    def __init__(self, rig: RigConfig) -> None:
        self.rig = rig
        self.ids = rig.ids
        spec = next(iter(rig.servos.values())).spec  # every X-series model has the same layout
        self.address = spec.spec(Item.PRESENT_POSITION).address
        self.length = spec.spec(Item.PRESENT_TEMPERATURE).end - self.address
        self._volt_at = spec.spec(Item.PRESENT_INPUT_VOLTAGE).address - self.address
        self._temp_at = spec.spec(Item.PRESENT_TEMPERATURE).address - self.address
        self.status_spec: ItemSpec = spec.spec(Item.HARDWARE_ERROR_STATUS)
        self.fast_capable = all(s.spec.fast_sync_read for s in rig.servos.values())
        n = len(self.ids)
        self.present_deg: list[float | None] = [None] * n
        self.voltage_v: list[float | None] = [None] * n
        self.temperature_c: list[int | None] = [None] * n
        self.restart()

    def restart(self) -> None:
        """Back to Fast Sync Read, nobody missing (a new start)."""
        self.use_fast = self.rig.bus.fast_sync_read and self.fast_capable
        self.retrying = False
        self._plain_next = False
        self._fast_failures = 0
        self._missing_since: list[float | None] = [None] * len(self.ids)

    def read(self, bus: SdkBus, skip: set[int], now: float, counters: BusCounters) -> None:
        """One read of every servo not in ``skip``. Raises ServoSilent (a servo missing for
        the reply budget) or ServoHardwareError (a servo raised its Alert bit)."""
        fast = self.use_fast and not self._plain_next
        ids = [sid for sid in self.ids if sid not in skip]
        failure: ServoSilent | None = None
        try:
            block = bus.read_block(self.address, self.length, ids, fast)
        except ServoSilent as exc:
            block, failure = exc.partial, exc
        for i, sid in enumerate(self.ids):
            if sid in block:
                self._missing_since[i] = None
            elif sid in ids and self._missing_since[i] is None:
                self._missing_since[i] = now
        for sid in self._decode(block):
            raise_hardware_error(bus, sid, self.status_spec)
        if failure is None:
            counters.reads += 1
            self.retrying = self._plain_next = False
            return
        counters.read_failures += 1
        self.retrying = True  # read again next tick, not in read_divider ticks
        if fast:
            counters.fast_read_failures += 1
            self._fast_failures += 1
            self._plain_next = True  # a plain Sync Read names the silent servo
            if self._fast_failures >= self.rig.bus.fast_read_fallback_after:
                self.use_fast = False
                log.warning("fast sync read failed %d times: using plain sync read", self._fast_failures)
        budget = self.rig.bus.reply_budget_s
        stale = {
            sid: since
            for sid, since in zip(self.ids, self._missing_since, strict=True)
            if since is not None and now - since >= budget
        }
        if stale:
            sid = failure.servo_id if failure.servo_id in stale else min(stale, key=stale.__getitem__)
            silent_ms = (now - stale[sid]) * 1000
            raise ServoSilent(sid, f"no reply for {silent_ms:.0f} ms of retries ({failure})") from failure

    def tracking_error(self, goals: Sequence[float]) -> list[float | None]:
        """Goal sent minus present position, degrees (None until read)."""
        return [None if p is None else g - p for g, p in zip(goals, self.present_deg, strict=True)]

    def _decode(self, block: dict[int, tuple[int, bytes]]) -> list[int]:
        """Store what a read brought; return the ids whose ERR byte has the Alert bit."""
        alerts = []
        for i, sid in enumerate(self.ids):
            if sid not in block:
                continue
            error, data = block[sid]
            self.present_deg[i] = pulses_to_deg(int.from_bytes(data[0:4], "little", signed=True))
            self.voltage_v[i] = int.from_bytes(data[self._volt_at : self._volt_at + 2], "little") / 10.0
            self.temperature_c[i] = data[self._temp_at]
            if error & ALERT_BIT:
                alerts.append(sid)
        return alerts


def raise_hardware_error(bus: SdkBus, servo_id: int, status: ItemSpec) -> None:
    """A servo set the Alert bit: read its Hardware Error Status (retried once) and raise.

    If it cannot be read, the Alert bit alone is proof enough: the bits are ("alert",).
    """
    for attempt in range(2):
        try:
            raw = bus.read(servo_id, status)
        except ServoSilent:
            if attempt:
                raise ServoHardwareError(servo_id, ("alert",), 0) from None
            continue
        if raw:
            raise ServoHardwareError(servo_id, hardware_bits(raw), raw)
        return
