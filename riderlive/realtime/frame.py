"""A tick's result as the typed frame every device gets (:class:`~riderlive.tickframe.TickFrame`:
metres and degrees, built once per tick at the edge of the tick's core)."""

from __future__ import annotations

import math

from riderlive.realtime.core import Driver, TickResult
from riderlive.tickframe import Flag, TickFrame

_DRIVER_FLAGS = {Driver.INPUT: Flag.INPUT, Driver.PROCEDURAL: Flag.PROCEDURAL, Driver.NEUTRAL: Flag.NEUTRAL}


def frame_of(  # noqa: PLR0917
    result: TickResult, tick: int, t: float, at: float, metres_per_unit: float, held: bool = False
) -> TickFrame:
    """The tick's typed frame (metres, degrees) of ``result`` (service units): tick index,
    engine time ``t``, deadline ``at`` (perf_counter s); ``held``: the last good result again."""
    flags = _DRIVER_FLAGS[result.driver]
    if not math.isnan(result.estimate[0]):
        flags |= Flag.SADDLE_INPUT
    if held:
        flags |= Flag.HELD
    return TickFrame.build(
        tick,
        t,
        at,
        result.source_time,
        flags,
        result.rider,
        result.horse,
        result.saddle,
        result.estimate,
        metres_per_unit,
    )
