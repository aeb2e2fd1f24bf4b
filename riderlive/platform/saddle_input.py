"""The platform's input from a frame file: saddle frames as they are, horse frames via their saddle pose.

A table with all six ``saddle.*`` channels (``channels.SADDLE``) is used as it is. A
table of horse frames (it has the rear pivot's pose, ``rearPivot.tx`` ... ``rz``) is
turned into the saddle pose by :func:`riderlive.saddle.saddle_matrix` at the default
saddle point; horse channels it omits count as zero (``riderlive.bake.horse_matrix``).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from riderlive.bake import horse_matrix
from riderlive.channels import SADDLE_NAMES
from riderlive.framefile import FrameFileError, FrameTable
from riderlive.saddle import SaddlePoint, saddle_matrix
from riderlive.saddle.pose import TRUNK_CHANNELS

FloatArray = npt.NDArray[np.float64]
SADDLE_CHANNELS: tuple[str, ...] = SADDLE_NAMES
"""The saddle pose channels, in pose order (m, deg; the rig frame of riderlive.channels)."""


def saddle_pose(table: FrameTable, source: str = "<take>", point: SaddlePoint | None = None) -> FloatArray:
    """``(N, 6)`` saddle poses for every frame of ``table`` (saddle or horse frames)."""
    if all(name in table.names for name in SADDLE_CHANNELS):
        return np.column_stack([table.column(name) for name in SADDLE_CHANNELS])
    if all(name in table.names for name in TRUNK_CHANNELS):
        return saddle_matrix(horse_matrix(table), point)
    raise FrameFileError(source, f"needs the saddle channels {', '.join(SADDLE_CHANNELS)} or horse frames")
