"""A take's timecode: the start label its sidecar carries, and replaying "from TC".

The recorder's sidecar (``NAME.json``) holds ``timecode`` (the label of the first row),
``timecode_rate`` and ``timecode_source`` (producer, stage or host); row ``k`` of a
take at time ``t`` is at the start label plus ``t`` seconds at the rate's real fps
(docs/timecode.md). Pure: the caller reads the sidecar.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from riderlive import timecode as tc
from riderlive.timecode import Anchor, Rate, TimecodeError


@dataclass(frozen=True)
class TakeTimecode:
    """Label ``frames`` at the take's first row, at ``rate``."""

    frames: int
    rate: Rate
    source: str

    @property
    def label(self) -> str:
        return tc.format_frames(self.frames, self.rate)

    def anchor(self, t0: float) -> Anchor:
        """The take's labels on its own clock (``t0``: the first row's time)."""
        return Anchor(t0, self.frames, self.rate)

    def at_rate(self, rate: Rate) -> TakeTimecode:
        """The same instant at another rate (the frame showing at it)."""
        if rate is self.rate:
            return self
        seconds = tc.frames_to_seconds(self.frames, self.rate)
        return TakeTimecode(tc.seconds_to_frames(seconds, rate), rate, self.source)

    def as_meta(self) -> dict[str, Any]:
        return {"timecode": self.label, "timecode_rate": self.rate.value, "timecode_source": self.source}


def take_timecode(meta: dict[str, Any] | None) -> TakeTimecode | None:
    """The timecode a sidecar carries; None when it has none (a take from before timecode).
    TimecodeError when it carries a broken one (a hand-edited sidecar)."""
    if not meta or "timecode" not in meta:
        return None
    rate = tc.parse_rate(meta.get("timecode_rate"))
    return TakeTimecode(tc.parse(meta["timecode"], rate), rate, str(meta.get("timecode_source", "unknown")))


def start_index(t: npt.NDArray[np.float64], stamp: TakeTimecode | None, from_tc: str, name: str) -> int:
    """The row nearest label ``from_tc`` (at the take's rate) in a take whose rows are at
    times ``t`` (increasing): at most half a row period (half a tick of the recording) from
    it. ValueError when the take has no timecode or the label is outside it."""
    if stamp is None:
        raise ValueError(f"take {name!r} has no timecode (recorded before timecode was stamped)")
    try:
        frames = tc.parse(from_tc, stamp.rate)
    except TimecodeError as exc:
        raise ValueError(f"from_tc: {exc}") from None
    offset = tc.frames_between(frames, stamp.frames, stamp.rate) / float(tc.RATES[stamp.rate].fps)
    elapsed = t - t[0]
    if not 0.0 <= offset <= float(elapsed[-1]) + 1e-9:
        end = stamp.anchor(float(t[0])).label_at(float(t[-1]))
        raise ValueError(f"from_tc {from_tc} is outside take {name!r} ({stamp.label} to {end} at {stamp.rate.value})")
    after = int(np.searchsorted(elapsed, offset))
    return (
        after - 1
        if after == len(t) or (after > 0 and offset - elapsed[after - 1] <= elapsed[after] - offset)
        else after
    )
