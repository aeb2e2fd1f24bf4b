"""The platform's input from a frame file: saddle frames as they are, horse frames via their saddle pose.

A table with all six ``saddle.*`` channels is used as it is. A table of horse frames
is turned into the saddle pose by :mod:`riderlive.saddle` when that package is
present; until then by the interim stand-in below (the rear pivot's displacement and
attitude, which is where the procedural horse's trunk motion lives), so bakes of
horse takes work today and switch over by themselves.
"""

from __future__ import annotations

import importlib

import numpy as np
import numpy.typing as npt

from riderlive.framefile import FrameFileError, FrameTable
from riderlive.platform.geometry import POSE_AXES

FloatArray = npt.NDArray[np.float64]
SADDLE_CHANNELS: tuple[str, ...] = tuple(f"saddle.{a}" for a in POSE_AXES)
"""The saddle pose channels, in pose order (m, deg; the rig frame of riderlive.channels)."""
INTERIM_CHANNELS: tuple[str, ...] = tuple(f"rearPivot.{a}" for a in POSE_AXES)


def _saddle_module() -> object | None:
    try:
        return importlib.import_module("riderlive.saddle")
    except ImportError:
        return None


def saddle_pose(table: FrameTable, source: str = "<take>") -> FloatArray:
    """``(N, 6)`` saddle poses for every frame of ``table`` (saddle or horse frames)."""
    if all(name in table.names for name in SADDLE_CHANNELS):
        return np.column_stack([table.column(name) for name in SADDLE_CHANNELS])
    if all(name in table.names for name in INTERIM_CHANNELS):
        module = _saddle_module()
        convert = getattr(module, "saddle_from_table", None) if module is not None else None
        if callable(convert):
            return np.asarray(convert(table), dtype=np.float64)
        return np.column_stack([table.column(name) for name in INTERIM_CHANNELS])
    raise FrameFileError(source, f"needs the saddle channels {', '.join(SADDLE_CHANNELS)} or horse frames")
