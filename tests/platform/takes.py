"""Saddle takes for the platform tests: every shot of config/shots/ and steady gaits, as (N, 6) arrays.

The saddle pose comes from riderlive.platform.saddle_input (riderlive.saddle when present).
Shots get their last segment lengthened so the seconds after the move fit in the take
(the shipped shots end 1.5 s after their move; the return is checked over 2 s).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np

from riderlive.configfile import CONFIG_DIR
from riderlive.horse import generate, load_script
from riderlive.horse.gaits import GAIT_TABLE, Gait, parse_gait
from riderlive.horse.moves import MOVE_TABLE, parse_move
from riderlive.horse.script import gait_script
from riderlive.platform.saddle_input import saddle_pose

RATE = 120.0
SHOTS = tuple(sorted(p.stem for p in (CONFIG_DIR / "shots").glob("*.toml")))
TAIL_S = 3.0
"""Seconds added to a shot's last segment."""


@dataclass(frozen=True)
class Take:
    saddle: np.ndarray  # (N, 6)
    t: np.ndarray
    move: tuple[float, float] | None  # start and end of the shot's move (s)
    after_stride_hz: float | None  # stride frequency of the gait after the move (None: halt)
    before: tuple[float, float] | None  # the gait segment before the move (s)


@cache
def shot(name: str) -> Take:
    script = load_script(Path(CONFIG_DIR / "shots" / f"{name}.toml"))
    segments = list(script.segment)
    last = segments[-1]
    segments[-1] = last.model_copy(update={"seconds": (last.seconds or 0.0) + TAIL_S})
    script = script.model_copy(update={"segment": segments})
    t = 0.0
    move = before = None
    after: float | None = None
    for seg in segments:
        if seg.move:
            move = (t, t + MOVE_TABLE[parse_move(seg.move)].duration)
            t = move[1]
            continue
        assert seg.seconds is not None
        if move is None:
            before = (t, t + seg.seconds)
        elif after is None:
            gait = parse_gait(seg.gait or "halt")
            after = (
                0.0 if gait is Gait.HALT else GAIT_TABLE[gait].frequency_at(seg.speed or GAIT_TABLE[gait].default_speed)
            )
        t += seg.seconds
    table = generate(script, rate=RATE)
    return Take(saddle_pose(table), table.times(RATE), move, after or None, before)


@cache
def gait(name: str, seconds: float = 10.0) -> tuple[np.ndarray, float]:
    """A steady gait's saddle take and its stride frequency (Hz)."""
    table = generate(gait_script(name, seconds), rate=RATE)
    g = parse_gait(name)
    return saddle_pose(table), GAIT_TABLE[g].frequency_at(GAIT_TABLE[g].default_speed)
