"""The platform's input from a frame file: saddle frames as they are, horse frames via their saddle pose.

A table with all six ``saddle.*`` channels (``channels.SADDLE``) is used as it is
(metres and degrees). A table of horse frames (it has the rear pivot's pose,
``rearPivot.tx`` ... ``rz``) is turned into the saddle pose by
:func:`riderlive.saddle.saddle_matrix` at ``point`` (the live service's ``[saddle]``
point; None: the default), its lengths first converted to metres (``metres_per_unit``,
:mod:`riderlive.units`); horse channels it omits count as zero
(:func:`riderlive.framefile.horse_matrix`).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from riderlive.channels import SADDLE_NAMES
from riderlive.framefile import FrameFileError, FrameTable, horse_matrix
from riderlive.saddle import SaddlePoint, saddle_matrix
from riderlive.saddle.pose import TRUNK_CHANNELS
from riderlive.units import horse_lengths

FloatArray = npt.NDArray[np.float64]
SADDLE_CHANNELS: tuple[str, ...] = SADDLE_NAMES
"""The saddle pose channels, in pose order (m, deg; the rig frame of riderlive.channels)."""


def saddle_pose(
    table: FrameTable, source: str = "<take>", point: SaddlePoint | None = None, metres_per_unit: float = 1.0
) -> FloatArray:
    """``(N, 6)`` saddle poses (m, deg) for every frame of ``table`` (saddle frames, or horse frames
    whose lengths are ``metres_per_unit`` m each)."""
    if all(name in table.names for name in SADDLE_CHANNELS):
        return np.column_stack([table.column(name) for name in SADDLE_CHANNELS])
    if all(name in table.names for name in TRUNK_CHANNELS):
        horse = horse_lengths(metres_per_unit).rows_to_metres(horse_matrix(table))
        return saddle_matrix(horse, point)
    raise FrameFileError(source, f"needs the saddle channels {', '.join(SADDLE_CHANNELS)} or horse frames")
