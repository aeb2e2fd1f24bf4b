"""SMPTE timecode (SMPTE 12-1): labels, frame counts and seconds at the nine stage rates.

Pure: no clocks, no I/O. A timecode is a frame count since ``00:00:00:00`` at one
:class:`Rate`, wrapping after 24 hours (``frames_per_day``). Drop-frame rates (29.97 DF,
59.94 DF) skip the labels ``;00`` and ``;01`` (``;00``-``;03`` at 59.94) of every minute
not divisible by ten, so that the label tracks wall-clock time: one hour of labels is
3599.9964 s of real time at 29.97 (``30000/1001`` frames per second; 86.4 ms a day).
23.976 is *not* drop-frame (SMPTE has none for it): its labels run at 24 per "second"
and fall behind the wall clock by 0.1 %.

Drop-frame labels are written with ``;`` before the frames (``01:00:00;02``), the
others with ``:``. :func:`parse` is strict about it: a ``:`` label at a drop-frame rate
(or a ``;`` one at another) is from a producer at another rate and is refused.

The PyPI ``timecode`` library (1.5) is the test oracle (``tests/test_timecode.py``) where
it is right; what it does differently is listed in ``docs/timecode.md``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from enum import StrEnum
from fractions import Fraction
from typing import Any

import numpy as np
import numpy.typing as npt

IntArray = npt.NDArray[np.int64]


class TimecodeError(ValueError):
    """A timecode or rate that cannot be used; ``reason`` is a metrics label."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


class Rate(StrEnum):
    """The stage rates; the value is how config files and the wire name them."""

    FPS_23_976 = "23.976"
    FPS_24 = "24"
    FPS_25 = "25"
    FPS_29_97_DF = "29.97df"
    FPS_30 = "30"
    FPS_48 = "48"
    FPS_50 = "50"
    FPS_59_94_DF = "59.94df"
    FPS_60 = "60"


@dataclass(frozen=True)
class RateFacts:
    """One rate: ``nominal`` labels per second, the real frame rate ``fps`` (frames per
    second of wall-clock time) and ``drop`` labels skipped per minute (not every tenth)."""

    nominal: int
    fps: Fraction
    drop: int

    @property
    def frames_per_day(self) -> int:
        """Frames from 00:00:00:00 to 24:00:00:00 (the wrap)."""
        return self.nominal * 86400 - self.drop * (1440 - 144)

    @property
    def frames_per_minute(self) -> int:
        """Frames in a minute whose first labels are dropped."""
        return self.nominal * 60 - self.drop

    @property
    def frames_per_ten_minutes(self) -> int:
        return self.nominal * 600 - 9 * self.drop


RATES: dict[Rate, RateFacts] = {
    Rate.FPS_23_976: RateFacts(24, Fraction(24000, 1001), 0),
    Rate.FPS_24: RateFacts(24, Fraction(24), 0),
    Rate.FPS_25: RateFacts(25, Fraction(25), 0),
    Rate.FPS_29_97_DF: RateFacts(30, Fraction(30000, 1001), 2),
    Rate.FPS_30: RateFacts(30, Fraction(30), 0),
    Rate.FPS_48: RateFacts(48, Fraction(48), 0),
    Rate.FPS_50: RateFacts(50, Fraction(50), 0),
    Rate.FPS_59_94_DF: RateFacts(60, Fraction(60000, 1001), 4),
    Rate.FPS_60: RateFacts(60, Fraction(60), 0),
}
"""The facts of each rate (SMPTE 12-1; ST 12-3 for 48, 50, 59.94 and 60)."""
_FLOAT_FPS = {rate: float(facts.fps) for rate, facts in RATES.items()}

_LABEL = re.compile(r"(\d{2}):(\d{2}):(\d{2})([:;.,])(\d{2})")


def parse_rate(value: object) -> Rate:
    """A rate from its name (``"29.97df"``); TimecodeError naming the allowed ones."""
    try:
        if isinstance(value, bool) or not isinstance(value, str | int | float):
            raise ValueError(value)
        return Rate(str(value).strip().lower())
    except ValueError:
        allowed = ", ".join(r.value for r in Rate)
        raise TimecodeError("timecode_rate", f"timecode rate {value!r} is not one of {allowed}") from None


def fields_to_frames(fields: npt.ArrayLike, rate: Rate) -> IntArray:
    """(N, 4) hours, minutes, seconds, frames -> frames since 00:00:00:00 (vectorised; no validation)."""
    facts = RATES[rate]
    f = np.asarray(fields, dtype=np.int64)
    h, m, s, ff = f[..., 0], f[..., 1], f[..., 2], f[..., 3]
    minutes = 60 * h + m
    out: IntArray = (h * 3600 + m * 60 + s) * facts.nominal + ff - facts.drop * (minutes - minutes // 10)
    return out.astype(np.int64)


def frames_to_fields(frames: npt.ArrayLike, rate: Rate) -> IntArray:
    """Frames since 00:00:00:00 (any integers: wrapped into one day) -> (N, 4) hours,
    minutes, seconds, frames of their labels (vectorised)."""
    return np.stack(_fields(np.asarray(frames, dtype=np.int64), rate), axis=-1)


def _fields(f: Any, rate: Rate) -> tuple[Any, Any, Any, Any]:
    """Label fields of frame counts ``f``: an int, or an int64 array (element-wise). Operators
    only, so that one body serves the vectorised and the per-record (scalar) callers."""
    facts = RATES[rate]
    f = f % facts.frames_per_day
    if facts.drop:
        tens, rest = divmod(f, facts.frames_per_ten_minutes)
        # the first minute of ten keeps its labels; each later one skips `drop` at its start
        late = (rest - facts.drop) * (rest > facts.drop)
        f = f + 9 * facts.drop * tens + facts.drop * (late // facts.frames_per_minute)
    n = facts.nominal
    return f // (3600 * n), f // (60 * n) % 60, f // n % 60, f % n


def check_fields(h: int, m: int, s: int, ff: int, rate: Rate) -> None:
    """TimecodeError when the label does not exist at ``rate``."""
    facts = RATES[rate]
    if h >= 24 or m >= 60 or s >= 60:
        label = f"{h:02d}:{m:02d}:{s:02d}"
        raise TimecodeError("timecode_malformed", f"timecode {label}: hours < 24, minutes and seconds < 60")
    if ff >= facts.nominal:
        raise TimecodeError(
            "timecode_rate",
            f"timecode {h:02d}:{m:02d}:{s:02d}.{ff:02d}: frame {ff} does not exist at {rate.value} "
            f"(frames 00-{facts.nominal - 1}): another rate?",
        )
    if facts.drop and s == 0 and ff < facts.drop and m % 10:
        raise TimecodeError(
            "timecode_malformed",
            f"{h:02d}:{m:02d}:00;{ff:02d} is a dropped label at {rate.value} (minutes not divisible by 10 start at "
            f";{facts.drop:02d})",
        )


def parse(text: object, rate: Rate) -> int:
    """``HH:MM:SS:FF`` (``HH:MM:SS;FF`` at drop-frame rates) -> frames since 00:00:00:00.

    TimecodeError: ``timecode_malformed`` (not a label, out of range, a dropped label) or
    ``timecode_rate`` (the separator or the frame number of another rate).
    """
    if not isinstance(text, str):
        raise TimecodeError("timecode_malformed", f"a timecode is a string 'HH:MM:SS:FF', not {type(text).__name__}")
    match = _LABEL.fullmatch(text.strip())
    if match is None:
        raise TimecodeError("timecode_malformed", f"timecode {text[:32]!r} is not HH:MM:SS:FF (or HH:MM:SS;FF)")
    h, m, s, sep, ff = match.groups()
    drop = RATES[rate].drop > 0
    if drop != (sep in ";.,"):
        want = "HH:MM:SS;FF" if drop else "HH:MM:SS:FF"
        raise TimecodeError("timecode_rate", f"timecode {text!r} is not {want} as at {rate.value}: another rate?")
    fields = (int(h), int(m), int(s), int(ff))
    check_fields(*fields, rate)
    return int(fields_to_frames(np.array(fields), rate))


def format_frames(frames: int, rate: Rate) -> str:
    """The label of ``frames`` since 00:00:00:00 (wrapped into one day)."""
    h, m, s, ff = _fields(int(frames), rate)
    return f"{h:02d}:{m:02d}:{s:02d}{';' if RATES[rate].drop else ':'}{ff:02d}"


def seconds_to_frames(seconds: float, rate: Rate) -> int:
    """The frame showing at ``seconds`` of wall-clock time since 00:00:00:00 (floor; 1 µs of slack
    so that ``frames_to_seconds`` round-trips)."""
    return math.floor(seconds * RATES[rate].fps + 1e-6)


def frames_to_seconds(frames: int, rate: Rate) -> float:
    """Wall-clock seconds from 00:00:00:00 to the start of frame ``frames``."""
    return float(frames / RATES[rate].fps)


def frames_between(later: int, earlier: int, rate: Rate) -> int:
    """Frames from ``earlier`` to ``later`` on the 24-hour circle, in -day/2..day/2 (across midnight)."""
    day = RATES[rate].frames_per_day
    return (later - earlier + day // 2) % day - day // 2


@dataclass(frozen=True)
class Anchor:
    """A timecode reference: label ``frames`` (since 00:00:00:00) at time ``t`` (seconds on
    some clock: a producer's ``t``, the engine's); frames run at the rate's real ``fps``."""

    t: float
    frames: int
    rate: Rate

    def frames_at(self, t: float) -> int:
        """The frame showing at ``t`` on the anchor's clock (wrapped into one day)."""
        facts = RATES[self.rate]
        return (self.frames + math.floor((t - self.t) * self._fps + 1e-6)) % facts.frames_per_day

    @property
    def _fps(self) -> float:
        return _FLOAT_FPS[self.rate]

    def label_at(self, t: float) -> str:
        return format_frames(self.frames_at(t), self.rate)


JUMP_TOLERANCE_FRAMES = 1
"""A producer's label may differ from the one its own ``t`` predicts by one frame (rounding
of the instant it took the label at); more is a jump."""


def observe(previous: Anchor, t: float, frames: int) -> tuple[Anchor, int | None]:
    """A producer's new (``t``, label) against its previous anchor: the new anchor, and the
    jump in frames (label minus the predicted one) when it exceeds :data:`JUMP_TOLERANCE_FRAMES`."""
    jump = frames_between(frames, previous.frames_at(t), previous.rate)
    return Anchor(t, frames, previous.rate), (jump if abs(jump) > JUMP_TOLERANCE_FRAMES else None)
