"""The outputs-off read-back's schedule (devices/off_readback.py), hand-computed: every tick
for CONFIRM_FAST_S after the outputs went off while unconfirmed, then every IDLE_CHECK_S."""

from __future__ import annotations

from typing import Any, cast

from riderlive.devices.off_readback import CONFIRM_FAST_S, IDLE_CHECK_S, Found, OffReadback

PERIOD = 0.125
"""A tick (s): a binary fraction, so that the hand-computed times are exact."""


class Units:
    """A plug's read-back side: ``off`` is what the units report; every read-back is counted."""

    def __init__(self) -> None:
        self.is_open = True
        self.off = True
        self.reads: list[bool] = []

    def outputs_confirmed_off(self) -> bool:
        self.reads.append(self.off)
        return self.off


def readback(units: Units) -> OffReadback:
    return OffReadback(cast(Any, units), PERIOD)


def test_written_reads_back_a_tick_later_then_idles_once_confirmed() -> None:
    units = Units()
    off = readback(units)
    off.written(10.0)
    assert not off.confirmed
    assert off.check(10.0 + PERIOD / 2) is Found.NOT_DUE and units.reads == []
    assert off.check(10.0 + PERIOD) is Found.CONFIRMED and off.confirmed
    # that read-back was scheduled unconfirmed: the next is a tick later, then IDLE_CHECK_S apart
    assert off.check(10.0 + 2 * PERIOD) is Found.STILL_OFF
    assert off.check(10.0 + 3 * PERIOD) is Found.NOT_DUE
    assert off.check(10.0 + 2 * PERIOD + IDLE_CHECK_S) is Found.STILL_OFF
    assert units.reads == [True, True, True]


def test_a_unit_still_on_is_read_back_every_tick_for_confirm_fast_s_then_every_idle_check() -> None:
    units = Units()
    units.off = False
    off = readback(units)
    off.restart(0.0, 0.0)
    ticks = round(CONFIRM_FAST_S / PERIOD)
    assert [off.check(k * PERIOD) for k in range(ticks)] == [Found.NOT_OFF] * ticks
    assert not off.confirmed
    # past CONFIRM_FAST_S since the outputs went off: no longer every tick
    assert off.check(CONFIRM_FAST_S) is Found.NOT_OFF
    assert off.check(CONFIRM_FAST_S + PERIOD) is Found.NOT_DUE
    units.off = True
    assert off.check(CONFIRM_FAST_S + IDLE_CHECK_S) is Found.CONFIRMED


def test_a_closed_transport_is_not_read_back() -> None:
    units = Units()
    units.is_open = False
    off = readback(units)
    off.restart(0.0, 0.0)
    assert off.check(5.0) is Found.NOT_DUE and units.reads == [] and not off.confirmed
