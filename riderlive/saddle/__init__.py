"""The saddle motion stream: the saddle pose out of any horse, and a rider from a saddle alone.

- :mod:`riderlive.saddle.pose`: ``channels.SADDLE`` (``saddle.tx ty tz rx ry rz``) from
  any horse frame, and back (pure, scalar and NumPy from one source).

See ``docs/saddle.md``.
"""

from __future__ import annotations

from riderlive.saddle.pose import (
    BACK_MID,
    WITHERS,
    SaddlePoint,
    saddle_from_horse,
    saddle_from_trunk,
    saddle_matrix,
    trunk_from_saddle,
)

__all__ = [
    "BACK_MID",
    "WITHERS",
    "SaddlePoint",
    "saddle_from_horse",
    "saddle_from_trunk",
    "saddle_matrix",
    "trunk_from_saddle",
]
