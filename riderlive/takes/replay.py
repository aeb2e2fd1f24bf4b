"""Reading a take (or any horse frame file) back as a source at its original timing."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from riderlive.bake import horse_matrix
from riderlive.framefile import read_frames

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


def load_replay(path: Path, rate: float = 120.0) -> Replay:
    """Load a take; rows whose ``t`` does not increase are dropped."""
    table = read_frames(str(path))
    if len(table) == 0:
        raise ValueError(f"{path}: the take has no frames")
    times = table.times(rate)
    keep = np.concatenate(([True], np.diff(times) > 0.0))
    return Replay(path.stem, np.ascontiguousarray(times[keep]), np.ascontiguousarray(horse_matrix(table)[keep]))
