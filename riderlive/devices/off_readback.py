"""The read-back that a device's outputs are off while nothing moves (disarmed, parked,
e-stop, fault): every tick right after they went off, then now and then.

:class:`OffReadback` keeps when the next read-back is due and whether the last one
confirmed every unit off; :class:`~riderlive.devices.device.Device` acts on what a
read-back finds (counts it, repeats the outputs-off). Times are ``time.perf_counter``
seconds.
"""

from __future__ import annotations

from enum import Enum

from riderlive.devices.plug import Plug

CONFIRM_FAST_S = 1.0
"""After outputs go off, read them back every tick for this long, then every ``IDLE_CHECK_S``."""
IDLE_CHECK_S = 0.5
"""While off (disarmed, parked, e-stop, fault): read back that outputs are still off."""


class Found(Enum):
    """What :meth:`OffReadback.check` found."""

    NOT_DUE = "not due"
    """No read-back this tick (or the transport is closed)."""
    CONFIRMED = "confirmed"
    """Every unit reports off, for the first time since the outputs went off."""
    STILL_OFF = "still off"
    """Every unit reports off, as at the last read-back."""
    NOT_OFF = "not off"
    """A unit does not report off: the outputs-off must be repeated."""


class OffReadback:
    """When to read back that ``plug``'s outputs are off, and whether they were (``confirmed``)."""

    def __init__(self, plug: Plug, period_s: float) -> None:
        self.plug = plug
        self.period_s = period_s
        self.confirmed = True
        """The last read-back found every unit off (and nothing moved since)."""
        self._since: float | None = None
        self._next = 0.0

    def restart(self, now: float, first: float) -> None:
        """The outputs just went off (or must be seen off again): unconfirmed, read back
        every tick from ``first`` for ``CONFIRM_FAST_S``."""
        self.confirmed, self._since, self._next = False, now, first

    def written(self, now: float) -> None:
        """The outputs-off was just written: the first read-back a tick later."""
        self.restart(now, now + self.period_s)

    def check(self, now: float) -> Found:
        """Read back when due (every tick until confirmed for ``CONFIRM_FAST_S``, then every
        ``IDLE_CHECK_S``); :attr:`Found.NOT_OFF` leaves the repeat to the caller."""
        if now < self._next or not self.plug.is_open:
            return Found.NOT_DUE
        fast = not self.confirmed and (self._since is None or now - self._since < CONFIRM_FAST_S)
        self._next = now + (self.period_s if fast else IDLE_CHECK_S)
        if self.plug.outputs_confirmed_off():
            first, self.confirmed = not self.confirmed, True
            return Found.CONFIRMED if first else Found.STILL_OFF
        self.confirmed = False
        return Found.NOT_OFF
