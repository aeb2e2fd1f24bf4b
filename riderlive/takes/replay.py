"""Reading a take (or any horse frame file) back as a source at its original timing."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from riderlive.channels import HORSE_NAMES
from riderlive.framefile import horse_matrix, read_frames
from riderlive.frameunits import recorded_scale, rescale_lengths

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Replay:
    """A take's horse frames: times ``t`` (s, increasing) and ``horse`` (N, len(HORSE))."""

    name: str
    t: FloatArray
    horse: FloatArray

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if len(self.t) else 0.0


def load_replay(
    path: Path,
    rate: float = 120.0,
    limits: tuple[list[float], list[float]] | None = None,
    length_scale: float | None = None,
) -> Replay:
    """Load a take; rows whose ``t`` does not increase are dropped.

    ``length_scale``: the service's; lengths are converted from the one recorded beside
    the take (``riderlive.frameunits``), if any. ``limits``: lowest and highest value per
    horse channel (``riderlive.ranges``, service units); a value outside is a ValueError
    naming take, row, channel and range.
    """
    table = read_frames(str(path))
    recorded = recorded_scale(str(path))
    if length_scale is not None and recorded is not None:
        table = rescale_lengths(table, recorded / length_scale)
    if len(table) == 0:
        raise ValueError(f"{path.name}: the take has no frames")
    times = table.times(rate)
    keep = np.concatenate(([True], np.diff(times) > 0.0))
    horse = horse_matrix(table)
    if limits is not None:
        low, high = np.asarray(limits[0]), np.asarray(limits[1])
        bad = np.argwhere((horse < low) | (horse > high))
        if len(bad):
            row, column = (int(i) for i in bad[0])
            raise ValueError(
                f"{path.name}: row {row + 1}: {HORSE_NAMES[column]} = {horse[row, column]!r} is outside its "
                f"plausible range [{low[column]:g}, {high[column]:g}]"
            )
    return Replay(path.stem, np.ascontiguousarray(times[keep]), np.ascontiguousarray(horse[keep]))
