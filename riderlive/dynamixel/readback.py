"""The divided read: what the servos report back, and which of them went silent.

Every ``read_divider`` ticks the plug reads 15 bytes from each servo, Present Position
(132) .. Present Temperature (146), with one Fast Sync Read (a single reply packet for
the whole bus) or a plain Sync Read (one reply per servo, so a silent servo is
named). Each servo's status ERR byte comes along; its Alert bit means "read my
Hardware Error Status".

Telling a miss from a failure (as ROS 2's Dynamixel hardware interface does):

- A failed read is retried on the next tick and counted; a servo is declared silent
  only when it has missed every read for ``reply_budget_s`` of usable time: the time
  the host itself could not run (steal, this thread's run-queue wait;
  :mod:`riderlive.devices.stall`) is not charged to it, and a silence that outlived the
  wall-clock budget only thanks to that discount is counted (``stall_ridethroughs``).
- The bus has an error budget (:class:`~riderlive.devices.budget.ErrorBudget`): every
  failed read adds one, every good one takes ``bus_error_credit`` out; failures that
  outnumber good reads by ``bus_error_burst`` (persistent corruption) are a
  ``bus_errors`` fault, scattered misses never are.
- A failed Fast Sync Read is followed by a plain one (which names a culprit). Only
  ``fast_read_fallback_after`` fast failures in a row, with no fast success between,
  switch to the plain read; it tries the fast read again after ``fast_read_retry_s``
  (doubling each time it fails again at once).
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Sequence

from riderlive.devices.budget import ErrorBudget
from riderlive.devices.lifecycle import BusErrors, HardwareFault, NoReply
from riderlive.devices.stall import HostClock, Sampler, SilenceState, lost_between, silence_step, usable_between
from riderlive.dynamixel.bringup import servo_hardware_error
from riderlive.dynamixel.rig import RigConfig
from riderlive.dynamixel.sdkbus import SdkBus
from riderlive.dynamixel.servo_map import pulses_to_deg
from riderlive.dynamixel.tables import ALERT_BIT, Item, ItemSpec

log = logging.getLogger("riderlive.dynamixel")
MAX_FAST_RETRY_S = 600.0


class Readback:
    """The read's state (fast or plain, retrying, who is missing) and the latest values."""

    def __init__(self, rig: RigConfig, host: Sampler | None = None) -> None:
        self.rig = rig
        self.host: Sampler = HostClock() if host is None else host
        """Where the host's stalls are read (only while a servo is silent)."""
        self.ids = rig.ids
        spec = next(iter(rig.servos.values())).spec  # every X-series model has the same layout
        self.address = spec.spec(Item.PRESENT_POSITION).address
        self.length = spec.spec(Item.PRESENT_TEMPERATURE).end - self.address
        self._volt_at = spec.spec(Item.PRESENT_INPUT_VOLTAGE).address - self.address
        self._temp_at = spec.spec(Item.PRESENT_TEMPERATURE).address - self.address
        self.status_spec: ItemSpec = spec.spec(Item.HARDWARE_ERROR_STATUS)
        self.fast_capable = rig.bus.fast_sync_read and all(s.spec.fast_sync_read for s in rig.servos.values())
        self.budget = ErrorBudget(rig.bus.bus_error_burst, rig.bus.bus_error_credit)
        n = len(self.ids)
        self.present_deg: list[float | None] = [None] * n
        self.voltage_v: list[float | None] = [None] * n
        self.temperature_c: list[int | None] = [None] * n
        self.fresh: set[int] = set()
        """The servos the last read heard from."""
        self.restart()

    def restart(self) -> None:
        """Back to Fast Sync Read, nobody missing, a full error budget (a new start)."""
        self.use_fast = self.fast_capable
        self.retrying = False
        self._plain_next = False
        self._fast_failures = 0
        self._probing = False
        self._fast_retry_at: float | None = None
        self._retry_interval = self.rig.bus.fast_read_retry_s
        self.silence = SilenceState.fresh(len(self.ids))
        self.silent: dict[int, tuple[float, float]] = {}
        """Each silent servo at the last read: ms of silence charged, ms the host stalled meanwhile."""
        self._rode_through: set[int] = set()
        self.budget.reset()

    def read(self, bus: SdkBus, skip: set[int], now: float, counters: Counter[str]) -> None:
        """One read of every servo not in ``skip``. Raises NoReply (a servo silent for its
        budget), BusErrors (the bus's budget is spent) or HardwareFault (an Alert bit)."""
        if not self.use_fast and self._fast_retry_at is not None and now >= self._fast_retry_at:
            self.use_fast, self._probing, self._fast_retry_at = True, True, None
            counters["fast_read_retries"] += 1
        fast = self.use_fast and not self._plain_next
        ids = [sid for sid in self.ids if sid not in skip]
        failure: NoReply | None = None
        try:
            block = bus.read_block(self.address, self.length, ids, fast)
        except NoReply as exc:
            block, failure = exc.partial, exc
        asked = [sid in ids for sid in self.ids]
        heard = [sid in block for sid in self.ids]
        quiet = any(a and not h for a, h in zip(asked, heard, strict=True))
        sample = self.host.sample(now) if quiet else None
        self.silence, over = silence_step(self.silence, asked, heard, sample, self.rig.bus.reply_budget_s)
        self.silent = {
            sid: (round(usable_between(since, sample) * 1000, 1), round(lost_between(since, sample) * 1000, 1))
            for sid, since in zip(self.ids, self.silence.since, strict=True)
            if since is not None and sample is not None
        }
        self._rode_through.intersection_update(i for i, h in enumerate(heard) if not h)
        self.fresh = set(block)
        for sid in self._decode(block):
            raise_hardware_error(bus, sid, self.status_spec)
        if failure is None:
            counters["reads"] += 1
            self.budget.ok()
            if fast:
                self._fast_failures = 0
                if self._probing:
                    self._probing, self._retry_interval = False, self.rig.bus.fast_read_retry_s
            self.retrying = self._plain_next = False
            return
        counters["read_failures"] += 1
        self.retrying = True  # read again next tick, not in read_divider ticks
        if fast:
            self._fast_failed(now, counters)
        if self.budget.fail():
            raise BusErrors(
                f"failed reads outnumber good ones by {self.budget.burst:g} "
                f"({self.budget.failures} failed, {self.budget.successes} good; last: {failure})"
            )
        self._count_ridethroughs(now, {o.index for o in over}, counters)
        if over:
            stale = {self.ids[o.index]: o for o in over}
            sid = failure.unit if failure.unit in stale else self.ids[over[0].index]
            o = stale[sid]
            lost = f", {o.lost_s * 1000:.0f} ms more while the host stalled" if o.lost_s >= 0.0005 else ""
            raise NoReply(sid, f"no reply for {o.usable_s * 1000:.0f} ms of retries{lost} ({failure})") from failure

    def _count_ridethroughs(self, now: float, over: set[int], counters: Counter[str]) -> None:
        """Count each silence that is past the budget on the wall clock but not in usable
        time (the host stalled): one per silence, however long it lasts."""
        budget = self.rig.bus.reply_budget_s
        for i, since in enumerate(self.silence.since):
            if since is None or i in over or i in self._rode_through:
                continue
            if now - since.wall_s >= budget:
                self._rode_through.add(i)
                counters["stall_ridethroughs"] += 1

    def _fast_failed(self, now: float, counters: Counter[str]) -> None:
        counters["fast_read_failures"] += 1
        self._fast_failures += 1
        self._plain_next = True  # a plain Sync Read names the silent servo
        if self._probing or self._fast_failures >= self.rig.bus.fast_read_fallback_after:
            if self._probing:
                self._retry_interval = min(2.0 * self._retry_interval, MAX_FAST_RETRY_S)
            self.use_fast, self._probing = False, False
            self._fast_retry_at = now + self._retry_interval
            counters["fast_read_fallbacks"] += 1
            log.warning(
                "fast sync read failed %d times in a row: plain sync read, fast again in %.0f s",
                self._fast_failures,
                self._retry_interval,
            )
            self._fast_failures = 0

    def tracking_error(self, goals: Sequence[float]) -> list[float | None]:
        """Goal sent minus present position, degrees; None for a servo the last read missed."""
        return [
            None if p is None or sid not in self.fresh else g - p
            for sid, g, p in zip(self.ids, goals, self.present_deg, strict=True)
        ]

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
        except NoReply:
            if attempt:
                raise HardwareFault(servo_id, ("alert",), 0, what="servo") from None
            continue
        if raw:
            raise servo_hardware_error(servo_id, raw)
        return
